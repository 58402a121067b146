"""``wmm-qp serve``'s command line: what it hands the daemon (no process started)."""

from __future__ import annotations

import pytest
from wmm_qp_service.commands import serve
from wmm_qp_tools.cli import build_parser, main


@pytest.mark.parametrize(("flags", "kind", "r"), [([], "position", 3), (["--task", "pose"], "pose", 6),
                                                   (["--task", "position"], "position", 3)])
def test_the_task_flag_sets_the_controllers_task(flags: list[str], kind: str, r: int) -> None:
    args = build_parser("serve").parse_args(["serve", *flags])
    task = serve.controller_config(args).task
    assert (task.kind, task.r) == (kind, r)


def test_an_unknown_task_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as e:
        main(["serve", "--task", "orientation"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "--task" in err and "'pose'" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
