"""The one progress reporter: counted work and open-ended notes on a stream."""

import io

import pytest

from hertzchain.progress import Progress


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_counted_work_reports_count_percentage_and_the_end():
    stream = io.StringIO()
    meter = Progress(4, "sweep (runs)", stream=stream, min_interval_s=0.0)
    for _ in range(4):
        meter.advance()
    lines = stream.getvalue().splitlines()
    assert len(lines) == 4
    assert lines[1].startswith("sweep (runs): 2/4 (50 %), ")
    assert lines[-1].startswith("sweep (runs): 4/4 (100 %), ") and "ETA 0.0 s" in lines[-1]


def test_notes_are_lines_with_the_elapsed_time_and_can_be_throttled():
    stream = io.StringIO()
    log = Progress(None, "fit", stream=stream, min_interval_s=3600.0)
    assert log.note("compiling")
    assert not log.note("iteration 1", throttle=True)  # within the interval: skipped
    assert log.note("iteration 2")  # unthrottled notes always write
    lines = stream.getvalue().splitlines()
    assert [line.split(", ")[0] for line in lines] == ["fit: compiling", "fit: iteration 2"]
    assert all(line.endswith(" s elapsed") for line in lines)
    with pytest.raises(ValueError, match="note"):
        log.advance()


def test_a_note_ends_a_terminal_line_rewritten_in_place():
    stream = _Terminal()
    meter = Progress(10, "diagnose", stream=stream, min_interval_s=0.0)
    meter.advance(3)
    meter.note("refit eta")
    text = stream.getvalue()
    assert text.startswith("\rdiagnose: 3/10 (30 %)")
    assert "\ndiagnose: refit eta, " in text and text.endswith(" s elapsed\n")


def test_a_stage_counts_elapsed_time_from_its_command_and_its_eta_from_its_own_rate():
    """A stage's reporter made with `since=outer.start` gives the time since the command
    started (not since the stage did), so its lines follow the command's on one clock."""
    stream = io.StringIO()
    outer = Progress(None, "diagnose", stream=stream)
    outer.start -= 40.0  # the command started 40 s ago
    outer.note("stage 2")
    stage = Progress(4, "diagnose: refitting candidates", stream=stream, min_interval_s=0.0, since=outer.start)
    stage.advance()
    note, line = stream.getvalue().splitlines()
    assert note.startswith("diagnose: stage 2, 40.")
    counted, elapsed, eta = line.split(", ")
    assert counted == "diagnose: refitting candidates: 1/4 (25 %)"
    assert 40.0 <= float(elapsed.removesuffix(" s elapsed")) < 45.0
    assert float(eta.removeprefix("ETA ").removesuffix(" s")) < 1.0  # 3 more at the stage's own (fast) rate
