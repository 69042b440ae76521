"""The ``>>>`` examples in the docstrings of the conventions modules are checked
(values worked out by hand: they document the frames and metrics, and fail when
either drifts)."""
import doctest

import pytest

import relight.frames
import relight.metrics


@pytest.mark.parametrize("module", [relight.frames, relight.metrics], ids=lambda m: m.__name__)
def test_docstring_examples(module):
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS, verbose=False)
    assert result.attempted >= 10, f"{module.__name__}: too few examples ({result.attempted})"
    assert result.failed == 0, f"{module.__name__}: {result.failed} doctest failures (see output above)"
