"""What the test modules share: fixtures of objects built once, fakes, stand-ins and the
helpers of the tests that start processes. No test module imports another test module; each
imports from here (``from support.x import ...``: ``tests/`` is on ``sys.path``, pyproject's
``pythonpath``)."""
