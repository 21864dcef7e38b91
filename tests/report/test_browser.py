"""The HTML reports in a real headless Chromium, offline from file://.

Debian's Chromium (installed by .ci/run) is driven through Playwright's protocol client with
name resolution disabled; every request must be file://, the console must stay free of
errors, and every plot container must have drawn content with a non-zero bounding box.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from helpers import REQUIRE_SHARED

#: a headless browser per page: the full suite, not the fast lane
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _need_browser():
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        if REQUIRE_SHARED:
            pytest.fail("UAVPIPE_REQUIRE_SHARED=1 but playwright is not installed")
        pytest.skip("playwright not installed")
    if not CHROMIUM:
        if REQUIRE_SHARED:
            pytest.fail("UAVPIPE_REQUIRE_SHARED=1 but Debian's chromium is not installed")
        pytest.skip("chromium not installed (apt-get install chromium)")


@pytest.fixture(scope="module")
def report_tree(tmp_path_factory) -> Path:
    """A results/ tree with the demo flight ingested, its report, plotly.js and the index."""
    from pipeline.simulate.demo import write_demo_flight
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.report.flight import build_flight_report, write_plotly_js
    from pipeline.report.index import build_index

    res = tmp_path_factory.mktemp("results")
    log = res / "sim" / "demo-quad.bin"
    log.parent.mkdir(parents=True)
    write_demo_flight(log, seed=1)
    run_ingest({"log": log}, outputs_for(res / "ingest" / "demo-quad"), None, flight_id="demo-quad")
    bad = res / "bad.bin"
    bad.write_bytes(b"garbage" * 50)
    run_ingest({"log": bad}, outputs_for(res / "ingest" / "bad"), None, flight_id="bad")
    write_plotly_js(res / "report" / "assets" / "plotly.min.js")
    for f in ("demo-quad", "bad"):
        build_flight_report(res / "ingest" / f, res / "report" / "flights" / f"{f}.html",
                            template=ROOT / "reports" / "templates" / "flight.html.j2",
                            plotly_js="../assets/plotly.min.js", index_href="../../index.html")
    # a tiny model trained on tiny simulated sets, evaluated, and its report
    from pipeline.models.run import run_evaluate, run_train
    from pipeline.report.model import build_model_report
    from pipeline.simulate.run import planned_sets, run_simulate_sets

    from pipeline.config import load_config

    cfg = load_config()   # validated: every default filled
    sim = cfg["simulate"]
    sim["datasets"] = {**sim["datasets"], "size": "tiny", "maneuvers": ["M1", "M2"],
                       "sizes": {"tiny": {"runs": 4, "mc_runs": 1, "switch_runs": 1, "log_flights": 0}}}
    sim["switch"] = {**sim["switch"], "times_s": [3]}
    run_simulate_sets({}, {"sets": [res / "sim" / "sets" / f"{n}.parquet" for n in planned_sets(sim)],
                           "summary": res / "sim" / "summary.parquet", "index": res / "sim" / "index.json"},
                      sim, seed=7)
    spec = {"data": "simulated", "labels": ["M1", "M2"], "vehicles": ["sim-quad"],
            "hmm": {**cfg["hmm"], "n_iter": 5, "gmm_restarts": 1, "init_min_samples": 20}}
    sets = [res / "sim" / "sets" / f"{m}_train.parquet" for m in ("M1", "M2")]
    model = {"params": res / "models" / "sim" / "params.npz", "meta": res / "models" / "sim" / "meta.json"}
    run_train({"sets": sets}, model, spec, model_set="sim", seed=cfg["seed"])
    run_evaluate({**model, "train_sets": sets,
                  "test_sets": [res / "sim" / "sets" / f"{m}_test.parquet" for m in ("M1", "M2")]},
                 {"evaluation": res / "models" / "sim" / "evaluation.parquet"}, spec, model_set="sim")
    build_model_report(res / "models" / "sim", res / "models" / "sim" / "evaluation.parquet",
                       res / "report" / "models" / "sim.html", template=ROOT / "reports" / "templates" / "model.html.j2",
                       plotly_js="../assets/plotly.min.js")
    build_index(["demo-quad", "bad"], [res / "ingest" / f / "meta.json" for f in ("demo-quad", "bad")],
                res / "index.html", links={f: f"report/flights/{f}.html" for f in ("demo-quad", "bad")},
                models={"sim": "report/models/sim.html"})
    return res


def _open(page_path: Path, shot: Path) -> dict:
    from playwright.sync_api import sync_playwright

    requests, console_errors, page_errors = [], [], []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=CHROMIUM, headless=True,
            args=["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  '--host-resolver-rules=MAP * ~NOTFOUND'])
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.on("request", lambda r: requests.append(r.url))
        page.on("console", lambda m: console_errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: page_errors.append(str(e)))
        page.goto(page_path.as_uri(), wait_until="load")
        page.wait_for_timeout(1500)
        plots = page.evaluate("""() => Array.from(document.querySelectorAll('.plotly-graph-div')).map(d => {
            const r = d.getBoundingClientRect();
            return {id: d.id, traces: (d.data || []).length, w: r.width, h: r.height,
                    drawn: d.querySelectorAll('.main-svg, canvas').length};
        })""")
        imgs = page.evaluate("() => Array.from(document.images).map(i => i.naturalWidth)")
        text = page.inner_text("body")
        page.screenshot(path=str(shot), full_page=True)
        browser.close()
    return {"requests": requests, "console": console_errors, "errors": page_errors, "plots": plots,
            "imgs": imgs, "text": text}


def _check_offline(r: dict) -> None:
    assert r["requests"], "no request recorded"
    bad = [u for u in r["requests"] if not u.startswith("file://")]
    assert not bad, f"non-file requests: {bad}"
    assert not r["console"], r["console"]
    assert not r["errors"], r["errors"]
    assert all(w > 0 for w in r["imgs"]), r["imgs"]


def test_index_in_headless_chromium(report_tree, tmp_path):
    _need_browser()
    r = _open(report_tree / "index.html", tmp_path / "index.png")
    _check_offline(r)
    assert "demo-quad" in r["text"] and "bad" in r["text"] and "failed" in r["text"]
    assert (tmp_path / "index.png").stat().st_size > 1000


def test_flight_report_in_headless_chromium(report_tree, tmp_path):
    _need_browser()
    r = _open(report_tree / "report" / "flights" / "demo-quad.html", tmp_path / "flight.png")
    _check_offline(r)
    assert len(r["plots"]) >= 5, r["plots"]
    for p in r["plots"]:
        assert p["traces"] > 0 and p["w"] > 0 and p["h"] > 0 and p["drawn"] > 0, p
    assert (tmp_path / "flight.png").stat().st_size > 1000


def test_model_report_in_headless_chromium(report_tree, tmp_path):
    _need_browser()
    r = _open(report_tree / "report" / "models" / "sim.html", tmp_path / "model.png")
    _check_offline(r)
    # training curves + one HMM figure per maneuver
    assert len(r["plots"]) == 3, r["plots"]
    for p in r["plots"]:
        assert p["traces"] > 0 and p["w"] > 0 and p["h"] > 0 and p["drawn"] > 0, p
    for table in ("Table 3.1", "Table 3.4"):
        assert table in r["text"]
    assert "98.21" in r["text"]  # the thesis's M1 MAoT beside ours
    assert (tmp_path / "model.png").stat().st_size > 1000


def test_zooming_one_time_panel_of_a_flight_page_zooms_the_others(report_tree):
    _need_browser()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True,
                                     args=["--no-sandbox", "--disable-gpu", '--host-resolver-rules=MAP * ~NOTFOUND'])
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.goto((report_tree / "report" / "flights" / "demo-quad.html").as_uri(), wait_until="load")
        page.wait_for_timeout(1000)
        ranges = page.evaluate("""async () => {
            const divs = Array.from(document.querySelectorAll('.plotly-graph-div')).slice(2);
            await Plotly.relayout(divs[0], {'xaxis.range': [10, 20]});
            await new Promise(r => setTimeout(r, 500));
            const first = divs.map(d => d.layout.xaxis.range.slice());
            // a mouse zoom reports the two ends separately
            await Plotly.relayout(divs[1], {'xaxis.range[0]': 30, 'xaxis.range[1]': 40});
            await new Promise(r => setTimeout(r, 500));
            return [first, divs.map(d => d.layout.xaxis.range.slice())];
        }""")
        browser.close()
    first, second = ranges
    assert len(first) >= 3, ranges
    assert all(r == [10, 20] for r in first), first
    assert all(r == [30, 40] for r in second), second


def test_a_bearing_replay_page_draws_offline_and_the_index_links_it(report_tree, tmp_path):
    _need_browser()
    import numpy as np
    import pandas as pd

    from pipeline.estimate.bearing_run import ESTIMATORS, run_bearing_replay
    from pipeline.io.parquet import write_table
    from pipeline.report.index import build_index

    t = np.arange(0, 15.0, 0.1)
    own = pd.DataFrame({"t_ns": (t * 1e9).astype(np.int64), "pos_n_m": 30 * t, "pos_e_m": 0 * t,
                        "vel_n_mps": 30 + 0 * t, "vel_e_mps": 0 * t})
    th = 0.1 * t
    intr = pd.DataFrame({"t_ns": (t * 1e9).astype(np.int64), "pos_n_m": -400 * np.sin(th),
                         "pos_e_m": 400 * np.cos(th) - 400, "vel_n_mps": 40 * np.cos(th), "vel_e_mps": 40 * np.sin(th)})
    write_table(own, tmp_path / "own.parquet")
    write_table(intr, tmp_path / "intr.parquet")
    out = {e: tmp_path / e / "syn.parquet" for e in ESTIMATORS}
    out.update({f"{e}_weights": tmp_path / e / "syn.weights.parquet" for e in ESTIMATORS})
    page = report_tree / "report" / "bearing" / "syn.html"
    out["page"] = page
    cfg = {"replay": {"syn": {"ownship": "own", "intruder": "intr", "duration_s": 10.0, "rate_hz": 5.0}}}
    assert run_bearing_replay({"ownship_state": tmp_path / "own.parquet", "intruder_state": tmp_path / "intr.parquet"},
                              out, cfg, pair="syn", seed=1).status == "ok"
    r = _open(page, tmp_path / "bearing.png")
    _check_offline(r)
    assert len(r["plots"]) == 1 and r["plots"][0]["traces"] >= 10 and r["plots"][0]["drawn"] > 0, r["plots"]
    index = report_tree / "index_bearing.html"
    build_index(["demo-quad"], [report_tree / "ingest" / "demo-quad" / "meta.json"], index,
                bearing={"syn": "report/bearing/syn.html"})
    text = index.read_text()
    assert "Bearing-only replays" in text and 'href="report/bearing/syn.html"' in text
