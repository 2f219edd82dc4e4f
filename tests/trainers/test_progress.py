"""The progress bar ends once: a line printed after training closes a full bar first instead of
redrawing it under the line (where `close` drew it a second time)."""

from __future__ import annotations

from selfplaydrive.trainers.ppo.logging import ProgressLogger


def test_a_line_after_the_last_update_closes_the_bar_once(capsys):
    logger = ProgressLogger(total_updates=2)
    logger.progress(1, {})
    logger.text("halfway")  # a line during training keeps the bar
    assert logger.bar is not None
    logger.progress(1, {"sps": 5.0})
    capsys.readouterr()
    logger.text("evaluation: done")
    out = capsys.readouterr()
    assert logger.bar is None and out.out == "evaluation: done\n"
    assert out.err.count("2/2") == 1 and out.err.endswith("\n")  # the final bar, drawn once
    logger.close()
    assert capsys.readouterr().err == ""  # nothing drawn again
