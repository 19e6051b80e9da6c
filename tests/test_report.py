"""report.json's run records (glsynth.data.report), by hand."""

import json

import pytest

from glsynth.core.errors import UserError
from glsynth.data.report import (
    RunTally,
    images_written,
    recorded_runs,
    run_record,
    tally_results,
    with_runs,
)


def _env(rows: int, pid: int, peak: int, render_s: float) -> dict:
    return {"kind": "env", "rows": [{}] * rows, "timings": {"render": render_s},
            "worker": {"pid": pid, "peak_rss_mib": peak}}


def _plates(train: int, test: int, pid: int, peak: int) -> dict:
    return {"kind": "plates", "rows": {"train": [[]] * train, "test": [[]] * test},
            "timings": {"render": 0.5, "plate damage textures": 2.0},
            "worker": {"pid": pid, "peak_rss_mib": peak}}


def test_images_are_kept_views_and_plates():
    assert images_written(_env(7, 1, 100, 1.0)) == 7
    assert images_written(_plates(3, 2, 1, 100)) == 5
    assert images_written(_env(0, 1, 100, 1.0)) == 0  # every view filtered out


def test_a_run_sums_phases_and_keeps_each_workers_peak():
    tally = tally_results([_env(4, 11, 300, 1.25), _plates(3, 1, 12, 500),
                           _env(2, 11, 350, 2.0), _env(1, 12, 450, 0.25)])
    assert tally == RunTally(images=11,
                             worker_seconds_by_phase={"render": 4.0,
                                                      "plate damage textures": 2.0},
                             worker_peak_rss_mib={11: 350, 12: 500})
    assert tally_results([]) == RunTally(0, {}, {})  # a resumed run with nothing left


def test_the_run_record_rounds_and_rates():
    tally = RunTally(10, {"render": 12.3456}, {3: 900, 1: 400})
    record = run_record(tally, "local", 2, 4.0049)
    assert record == {"engine": "local", "workers": 2, "wall_s": 4.0,
                      "images_written_this_run": 10, "images_per_s": 2.497,
                      "worker_seconds_by_phase": {"render": 12.35},
                      "worker_peak_rss_mib": [400, 900]}
    # No images, or no time: no rate rather than zero or a division by zero.
    assert run_record(RunTally(0, {}, {}), "ray", 4, 1.5)["images_per_s"] is None
    assert run_record(RunTally(3, {}, {}), "ray", 4, 0.0)["images_per_s"] is None


def test_every_run_stays_in_the_report_with_totals():
    first = run_record(RunTally(10, {}, {}), "local", 1, 5.0)
    second = run_record(RunTally(0, {}, {}), "local", 1, 0.25)
    report = with_runs({"kept": 8, "plates": 2}, [first], second)
    assert report["kept"] == 8 and report["runs"] == [first, second]
    assert report["wall_s"] == 0.25 and report["images_written_this_run"] == 0  # this run
    assert report["wall_s_all_runs"] == 5.25 and report["images_written_all_runs"] == 10
    # A run recorded without figures counts as none.
    blank = {**first, "wall_s": None, "images_written_this_run": None}
    assert with_runs({}, [blank], second)["wall_s_all_runs"] == 0.25


def test_recorded_runs_read_back_and_bad_reports_are_refused(tmp_path):
    report = tmp_path / "report.json"
    assert recorded_runs(report) == []  # a new dataset
    run = run_record(RunTally(1, {"render": 1.0}, {5: 10}), "local", 1, 2.0)
    report.write_text(json.dumps(with_runs({"kept": 1}, [], run)))
    assert recorded_runs(report) == [run]
    report.write_text("{truncated")
    with pytest.raises(UserError, match="report.json' is not valid JSON"):
        recorded_runs(report)
    for other, why in (({"wall_s": 3.0, "kept": 1}, "has no 'runs'"),
                       ([run], "holds a JSON list, not an object"),
                       ({"runs": "many"}, "runs = 'many' is not a list"),
                       ({"runs": [1]}, "runs holds other than run records")):
        report.write_text(json.dumps(other))
        with pytest.raises(UserError, match=f"dataset report .*{why}.*move it aside"):
            recorded_runs(report)
