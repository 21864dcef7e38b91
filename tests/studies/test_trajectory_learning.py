"""Study trajectory_learning at tiny size: the real-data leave-one-out on synthetic flights (fast),
and on the real FlightCoach / kd0aij flights when ../shared/realdata is there."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import need_shared
from helpers_align import synthetic_segments, synthetic_state, write_flight

from pipeline.config import load_config, section
from pipeline.io.parquet import read_table
from pipeline.studies import STUDIES, STUDY_TABLES, run_study, study_outputs


def _align(sets):
    a = section(load_config(), "align")
    a.update(sets=sets, max_iter=2)
    return a


def test_the_study_is_registered_with_its_tables():
    assert "trajectory_learning" in STUDIES
    assert STUDY_TABLES["trajectory_learning"] == ("sim_cases", "sim_summary", "real_loo", "real_summary")


def _real_loo_of_three_flights(tmp_path, segments):
    """The study's real part (tiny, 2 EM iterations) over three synthetic flights f0-f2 of set
    ``s``, flight k with ``segments(k)``: ``(result, outputs)``."""
    paths = [write_flight(tmp_path, f"f{k}", synthetic_state(260, heading_rad=0.3 * k, seed=k),
                          synthetic_segments(segments(k)), 0.3 * k) for k in range(3)]
    inputs = {"states": [p[0] for p in paths], "segments": [p[1] for p in paths]}
    out = study_outputs("trajectory_learning", results_dir=tmp_path / "results", models=False)
    res = run_study("trajectory_learning", inputs, out,
                    {"size": "tiny", "trajectory_learning": {"sets": ["s"], "skip": ["simulated"],
                                                             "sizes": {"tiny": {"real_max_iter": 2}}}},
                    seed=1, align=_align({"s": {"flights": ["f0", "f1", "f2"], "reference": None}}))
    return res, out


def _loo_results(loo) -> dict[str, str]:
    """The real part's RESULT values recomputed from the written ``real_loo`` rows by the study's
    rule (module docstring): a maneuver is better when its folds' mean learned-to-left-out distance
    is below their mean closest-other distance; a fold is better when its own is."""
    out: dict[str, str] = {}
    ok = loo[loo["status"] == "ok"]
    for frame, tag in (("box", ""), ("centred", "_centred")):
        fr = ok[ok["frame"] == frame]
        if not len(fr):
            continue
        man = []                                 # (better, better than DBA, has a two-demo fold)
        for _, g in fr.groupby(["set", "maneuver"], sort=False):
            learned = float(np.mean(g["rms_learned_m"].to_numpy()))
            man.append((learned < float(np.mean(g["rms_best_other_m"].to_numpy())),
                        learned < float(np.mean(g["rms_dba_m"].to_numpy())), bool(g["single_other"].any())))
        out[f"align_real_loo_better_pct{tag}"] = f"{100.0 * sum(b for b, _, _ in man) / len(man):.1f}"
        multi = [b for b, _, single in man if not single]
        if multi:
            out[f"align_real_loo_better_pct{tag}_3plus_demos"] = f"{100.0 * sum(multi) / len(multi):.1f}"
        if frame == "box":
            out["align_real_loo_better_than_dba_pct"] = f"{100.0 * sum(d for _, d, _ in man) / len(man):.1f}"
            out["align_real_loo_maneuvers"] = str(len(man))
            folds = fr[~fr["single_other"].astype(bool)]
            if len(folds):
                n = int(sum(a < b for a, b in zip(folds["rms_learned_m"], folds["rms_best_other_m"])))
                out["align_real_loo_folds_better_3plus_demos"] = f"{n}/{len(folds)}"
                ratio = folds["rms_best_other_m"].to_numpy() / folds["rms_between_others_m"].to_numpy()
                out["align_real_loo_closest_over_between_3plus_demos"] = f"{float(np.median(ratio)):.3f}"
    box = loo[loo["frame"] == "box"]
    status = box["status"].astype(str)
    scored = {(a, b) for a, b, st in zip(box["set"], box["maneuver"], status) if st == "ok"}
    out["align_real_loo_maneuvers_unscored"] = str(len(set(zip(box["set"], box["maneuver"])) - scored))
    out["align_real_loo_folds_failed"] = str(sum(st != "ok" and not st.startswith("skipped") for st in status))
    return out


def _check_real_results(out) -> None:
    """Every real-part RESULT line printed to ``results`` equals its recomputation from the
    written ``real_loo`` table, and ``real_summary``'s verdicts are the recomputed ones."""
    from pipeline.report.study import read_results

    printed = read_results(out["results"])
    loo, summ = read_table(out["real_loo"]), read_table(out["real_summary"])
    want = _loo_results(loo)
    got = {k: v for k, v in printed.items() if k.startswith("align_real_loo_")}
    ratio = "align_real_loo_closest_over_between_3plus_demos"
    assert set(got) == set(want)
    assert {k: v for k, v in got.items() if k != ratio} == {k: v for k, v in want.items() if k != ratio}
    if ratio in want:   # a median of ratios, printed to 3 decimals
        assert float(got[ratio]) == pytest.approx(float(want[ratio]), abs=5e-4 + 1e-12)
    ok = loo[loo["status"] == "ok"]
    for r in summ.itertuples():
        g = ok[(ok["frame"] == r.frame) & (ok["set"] == r.set) & (ok["maneuver"] == r.maneuver)]
        assert bool(r.better) == (float(np.mean(g["rms_learned_m"].to_numpy()))
                                  < float(np.mean(g["rms_best_other_m"].to_numpy()))), r


def test_the_real_leave_one_out_writes_a_row_per_fold_and_the_result_line(tmp_path):
    res, out = _real_loo_of_three_flights(tmp_path, lambda k: [(0, 5, "a"), (5, 10, "b")])
    loo = read_table(out["real_loo"])
    assert len(loo) == 12 and set(loo["status"]) == {"ok"}  # 2 maneuvers x 3 folds x (box, centred)
    assert loo.groupby("frame").size().to_dict() == {"box": 6, "centred": 6}
    assert "align_real_loo_better_pct_centred" in res.results
    assert np.isfinite(loo[["rms_learned_m", "rms_best_other_m", "rms_dba_m", "rms_between_others_m"]].to_numpy()).all()
    assert all(c.split(":")[0] in {"f0", "f1", "f2"} - {lo.split(":")[0]}
               for c, lo in zip(loo["closest_other"], loo["left_out"]))
    assert res.results["align_real_loo_folds_better_3plus_demos"].endswith("/6")  # 2 maneuvers x 3 folds, box
    # each printed share, count and ratio is its recomputation from the written fold rows
    _check_real_results(out)
    assert "RESULT align_real_loo_better_pct " in Path(out["results"]).read_text()
    assert "align_real_loo_better_pct" in Path(out["page"]).read_text()
    # what the shares leave out is counted: nothing here
    assert res.results["align_real_loo_maneuvers_unscored"] == "0" and res.results["align_real_loo_folds_failed"] == "0"


def test_a_maneuver_with_one_demo_is_counted_as_unscored_not_dropped_silently(tmp_path):
    # maneuver "c" is flown in one flight only: it has no leave-one-out, and the shares' denominator
    # leaves it out, so a RESULT line says so
    res, out = _real_loo_of_three_flights(tmp_path, lambda k: [(0, 5, "a"), (5, 10, "b" if k else "c")])
    assert res.results["align_real_loo_maneuvers_unscored"] == "1"
    assert res.results["align_real_loo_maneuvers"] == "2"
    _check_real_results(out)       # "b" has two demos: its folds are single_other, left out of 3plus


def test_a_set_whose_flights_are_absent_is_skipped_with_a_notice(tmp_path):
    out = study_outputs("trajectory_learning", results_dir=tmp_path / "results", models=False)
    res = run_study("trajectory_learning", {"states": [], "segments": []}, out,
                    {"size": "tiny", "trajectory_learning": {"sets": ["s"], "skip": ["simulated"]}},
                    seed=1, align=_align({"s": {"flights": ["gone1", "gone2"], "reference": None}}))
    assert "set s: no demos (its flights are not available): skipped" in res.diagnostics["notices"]
    assert "align_real_loo_better_pct" not in res.results


@pytest.fixture(scope="module")
def built_real_inputs(tmp_path_factory) -> dict:
    """The state and segment tables of the align sets' flights (P23/P21): the main job's under
    results/ when it has built them, else made here from their manifest rows by the workflow's
    own ingest and preprocess entry points (a clean clone, as in CI, has no results/: the
    real-data tests run there too)."""
    need_shared("FlightCoach JSON and kd0aij CSV flights")
    cfg = load_config()
    flights = list(dict.fromkeys(f for s in cfg["align"]["sets"].values() for f in s["flights"]))
    root = Path("results")
    if not all((root / "state" / f"{f}.parquet").exists() for f in flights):
        from helpers import REALDATA

        from pipeline.io.ingest import outputs_for, run_ingest
        from pipeline.io.manifest import check_manifest, expand_path
        from pipeline.preprocess.run import run_preprocess

        rows = {r["flight_id"]: r for r in check_manifest(cfg["manifest"], cfg)}
        root = tmp_path_factory.mktemp("results")
        for f in flights:
            ing = root / "ingest" / f
            run_ingest({"log": expand_path(rows[f]["path"], str(REALDATA))}, outputs_for(ing), cfg["ingest"],
                       flight_id=f, fmt=rows[f]["format"] or None)
            out = {k: root / k / f"{f}.parquet" for k in ("state", "segments", "calibration")}
            run_preprocess({"meta": ing / "meta.json"}, {**out, "info": root / "state" / f"{f}.json"},
                           cfg["preprocess"], vehicle=rows[f]["vehicle"])
    return {"states": [str(root / "state" / f"{f}.parquet") for f in flights],
            "segments": [str(root / "segments" / f"{f}.parquet") for f in flights]}


@pytest.mark.slow
def test_the_tiny_study_on_the_real_flights_prints_both_result_lines(tmp_path, built_real_inputs):
    inputs = built_real_inputs
    out = study_outputs("trajectory_learning", results_dir=tmp_path / "results", models=False)
    res = run_study("trajectory_learning", inputs, out, {"size": "tiny"}, seed=20261123,
                    align=section(load_config(), "align"))
    for name in ("align_real_loo_better_pct", "align_real_loo_better_pct_centred"):
        assert name in res.results, name
    # each printed share, count and ratio is its recomputation from the written fold rows
    _check_real_results(out)


def _circle(t, radius=80.0, speed=28.0, offset=(0.0, 0.0, 0.0)):
    w = speed / radius
    pos = np.column_stack([radius * np.sin(w * t), radius * (1 - np.cos(w * t)), -100.0 + 5.0 * np.sin(0.3 * t)])
    vel = np.gradient(pos, t, axis=0)
    return np.hstack([pos + np.asarray(offset), vel, np.gradient(vel, t, axis=0)])


def test_one_path_sampled_at_other_times_is_at_zero_distance_in_the_leave_one_out():
    from pipeline.studies.trajectory_learning import _path_rms

    # 3 Hz at 28 m/s: samples 9 m apart; the same path between the same ends sampled at 5.4 Hz
    t = np.arange(0.0, 12.0, 0.32)
    a, b = _circle(t), _circle(np.linspace(0.0, t[-1], 65))
    assert _path_rms(a, b) < 0.3  # was 2.6 m on the samples themselves
    assert _path_rms(a, a) == pytest.approx(0.0, abs=1e-9)
    # a real offset is measured as it is
    assert _path_rms(a, _circle(t, offset=(0.0, 0.0, 10.0))) == pytest.approx(10.0, abs=0.3)


def test_the_trajectory_learned_from_one_demo_is_as_close_to_its_twin_as_that_demo_is():
    from pipeline.align.demos import Demo
    from pipeline.studies.trajectory_learning import loo_maneuver

    t = np.arange(0.0, 15.0, 0.32)
    rng = np.random.default_rng(3)
    x = _circle(t)
    x[:, :3] += 0.05 * rng.standard_normal((len(t), 3))
    t_ns = (t * 1e9).astype(np.int64)
    demos = [Demo(f"f{k}:a#1", f"f{k}", "a", 0, t_ns, x.copy()) for k in range(2)]
    rows = loo_maneuver("s", "a", demos, _align({})  , max_iter=5)
    for r in rows:
        assert r["status"] == "ok" and r["single_other"] and r["rms_best_other_m"] == pytest.approx(0.0, abs=1e-9)
        # a smoother of the very demo it is compared with: at most the curve's chord error, not
        # the 3-5 m the sample-wise path read
        assert r["rms_learned_m"] < 0.5


def test_each_fold_names_its_closest_other_demo_and_how_far_apart_the_others_are():
    from pipeline.align.demos import Demo
    from pipeline.studies.trajectory_learning import loo_maneuver

    # three copies of one path offset along down by 0, 4 and 12 m: left-out A's closest other is B
    # (4 m), and B and C are 8 m apart, so A lies beside B rather than among B and C (ratio 0.5)
    t = np.arange(0.0, 15.0, 0.32)
    t_ns = (t * 1e9).astype(np.int64)
    demos = [Demo(f"f{k}:a#1", f"f{k}", "a", 0, t_ns, _circle(t, offset=(0.0, 0.0, dz)))
             for k, dz in enumerate((0.0, 4.0, 12.0))]
    rows = {r["left_out"]: r for r in loo_maneuver("s", "a", demos, _align({}), max_iter=3)}
    a = rows["f0:a#1"]
    assert a["closest_other"] == "f1:a#1" and a["rms_best_other_m"] == pytest.approx(4.0, abs=0.3)
    assert a["rms_between_others_m"] == pytest.approx(8.0, abs=0.3)
    assert rows["f2:a#1"]["closest_other"] == "f1:a#1" and rows["f1:a#1"]["closest_other"] == "f0:a#1"


def test_a_label_flown_twice_in_each_flight_is_one_maneuver_per_occurrence():
    from pipeline.align.run import by_occurrence

    class D:
        def __init__(self, name):
            self.name = name

    m = {"hB": [D("f1:hB#1"), D("f1:hB#2"), D("f2:hB#1"), D("f2:hB#2")], "loop": [D("f1:loop#1"), D("f2:loop#1")],
         "rollC": [D("f1:rollC#1"), D("f1:rollC#2"), D("f2:rollC#2")]}
    out = by_occurrence(m)
    assert list(out) == ["hB#1", "hB#2", "loop", "rollC#1", "rollC#2"]
    assert [d.name for d in out["hB#2"]] == ["f1:hB#2", "f2:hB#2"]
    assert [d.name for d in out["rollC#2"]] == ["f1:rollC#2", "f2:rollC#2"]


@pytest.mark.slow
@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="issue 15 real-data target missed on faithful code (box 44.1 %, centred 50.0 % of 34 "
                   "maneuvers): on the 23 two-demo maneuvers the learned trajectory interpolates its one "
                   "training demo and ties it within 0.23 m (12/23 'better' by that tie; fitting it on that "
                   "one demo alone instead of duplicated moves it by <= 0.08 m); on the 11 with three "
                   "or more it sits within a few m of the others' DBA average, and the demos differ by where "
                   "and how each pilot flew (kd0aij-141's rigid fit: 114 m pair RMS), not by independent noise, "
                   "so the closest single demo mostly wins (3/11)")
def test_the_trajectory_learned_from_the_other_demos_is_closer_on_80_pct_of_the_real_maneuvers(built_real_inputs):
    from pipeline.studies.trajectory_learning import DEFAULTS, real_part

    inputs = built_real_inputs
    _, summ, _ = real_part(inputs, section(load_config(), "align"), {**DEFAULTS, "frames": ["box"]},
                           lambda msg: None)
    # the precondition fails as a failure (pytest.fail raises Failed), not as the expected miss
    if len(summ) < 30:
        pytest.fail(f"precondition: at least 30 real maneuvers in the leave-one-out, got {len(summ)}")
    assert 100.0 * float(summ["better"].mean()) >= 80.0  # RESULT align_real_loo_better_pct


def test_the_two_leave_one_out_panels_name_their_frames():
    import pandas as pd

    from pipeline.studies.trajectory_learning import _figure

    s = pd.DataFrame({"set": ["p23"], "maneuver": ["M"], "rms_learned_m": [1.0], "rms_best_other_m": [2.0],
                      "rms_dba_m": [3.0]})
    box, centred = _figure(s), _figure(s, "each demo centred on its mean position")
    assert box.layout.title.text != centred.layout.title.text and "(box frame)" in box.layout.title.text
    assert box.layout.yaxis.title.text == "RMS distance [m]"
