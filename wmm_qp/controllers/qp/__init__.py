"""The QP controller (docs/model.md "The QP"): the stages' problems (:mod:`.stages`), how a stage is
solved (:mod:`.cascade`), the rows of a tick's stages (:mod:`.stage_rows`), the compiled kernels
(:mod:`.kernels`) and the stage logic (:mod:`.controller`)."""

from .controller import QpController

__all__ = ["QpController"]
