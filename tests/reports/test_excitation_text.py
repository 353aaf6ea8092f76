"""The excitation report's words for the criterion's change."""

from __future__ import annotations

import pytest

from idkit.reports.excitation import criterion_change


@pytest.mark.parametrize(
    ("criterion", "before", "after", "words"),
    [
        ("cond", 36.1, 6.645, "5.43 times smaller"),
        ("cond", 29.6, 35.6164, "1.20 times larger"),  # worse than a default that leaves the limits
        ("logdet", -3.0, 1.5, "+4.5"),
    ],
)
def test_the_change_says_smaller_or_larger_as_it_is(criterion, before, after, words):
    assert criterion_change(criterion, before, after) == words
