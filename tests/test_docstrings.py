"""The examples in the public docstrings run and print what they say."""

import doctest
import importlib

import pytest

MODULES = ["irtps.batch", "irtps.options", "irtps.output_rule", "irtps.paper_estimator", "irtps.placement", "irtps.radiometry", "irtps.residual", "irtps.render", "irtps.surface", "irtps.synth", "irtps.scene", "irtps.dataset", "irtps.imageio", "irtps.atomic", "irtps.diligent", "irtps.evaluate", "irtps.mesh", "irtps.integrate", "irtps.ps", "irtps.reconstruct", "irtps.display", "irtps.figures", "irtps.report", "irtps.report_page"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
    if name in ("irtps.batch", "irtps.options", "irtps.output_rule", "irtps.placement", "irtps.radiometry", "irtps.residual", "irtps.render", "irtps.surface", "irtps.synth", "irtps.evaluate", "irtps.mesh", "irtps.integrate", "irtps.ps", "irtps.reconstruct", "irtps.display", "irtps.figures", "irtps.report", "irtps.report_page"):
        assert result.attempted > 0
