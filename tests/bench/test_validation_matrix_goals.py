"""The validation matrix's goal lines count what they say, from rows as the bench writes them."""

from tests.bench.bench_validation_matrix import goals, table


def _row(cell: str, group: str, *, right_first=False, true_rank=None, significant=False) -> dict:
    return {"group": group, "cell": cell, "right_first": right_first, "true_rank": true_rank,
            "any_significant": significant, "top_significant": significant, "top": "X@n", "true_lookalike": False,
            "share_removed": 0.5, "true_share_removed": 0.5, "candidates": [], "signal_to_noise": None,
            "affected_sensor": "s"}


def test_goal_lines_tell_an_answer_from_a_top_rank():
    rows = [
        _row("leak (clear)", "catalog", right_first=True, true_rank=1, significant=True),
        _row("leak (clear)", "catalog", true_rank=1),  # first, below significance
        _row("lag (clear)", "catalog", true_rank=3, significant=True),  # a wrong answer
        _row("lag (subtle)", "catalog", true_rank=1),
        _row("fault-free", "fault-free", significant=True),
        _row("fault-free", "fault-free"),
    ]
    lines = goals(rows).splitlines()
    assert "clear 1/3 = 33%" in lines[0] and "subtle 0/1 = 0%" in lines[0]
    assert "clear 2/3 = 67%" in lines[1] and "subtle 1/1 = 100%" in lines[1]
    assert "1/2" in lines[2]
    assert "| leak (clear) | 2 | 1/2 | 2/2 |" in table(rows)
