"""The printed verdict lines: the failure shouts, the pass says how close, nothing without a verdict."""

from physinfer.adequacy import agreement_line, verdict, verdict_line


def test_a_passing_posterior_median_is_said_with_its_statistic():
    record = {**verdict(1.37, None, 1.0), "at": "posterior median"}
    assert verdict_line(record) is None
    assert agreement_line(record) == (
        "  the posterior median reproduces the video (1.37 times the scale of agreement, ≤ 10)"
    )


def test_a_refinement_passes_as_its_best_fit_and_a_failure_is_not_called_agreement():
    assert "the best fit reproduces the video (0.5 times" in agreement_line(verdict(0.5, 1.0, None))
    failing = verdict(50.0, 1.0, None)
    assert agreement_line(failing) is None
    assert verdict_line(failing).startswith("THE MODEL DOES NOT REPRODUCE THIS VIDEO")


def test_no_scale_means_no_line_either_way():
    unmeasured = verdict(1.0, None, None)
    assert unmeasured["reproduces"] is None
    assert agreement_line(unmeasured) is None and verdict_line(unmeasured) is None
    assert agreement_line(None) is None
