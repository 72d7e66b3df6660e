"""The HTML report and its figures: content, graceful degradation, the CLI, and a real headless browser."""

from __future__ import annotations

import base64
import hashlib
import io
import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import matplotlib.image as mpimg
import numpy as np
import pytest
from matplotlib.container import ErrorbarContainer
from matplotlib.figure import Figure

from mountcal import Options, calibrate, simulate_stops
from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.core.findings import Finding
from mountcal.core.result import Calibration
from mountcal.outputs.report import figures, render
from mountcal.outputs.report.document import angle_estimates, format_pm, step_label
from mountcal.outputs.report.embed import embed_svg
from mountcal.outputs.report.html import short_source
from mountcal.stops.table import StopTable, write_stop_table

BIAS_20MG = np.array([20.0, -10.0, 15.0]) * 1e-3 * 9.80665


@pytest.fixture(scope="module")
def paper_scenario() -> tuple[StopTable, Calibration]:
    """The paper's scenario (docs/conventions.md §3) with stop temperatures, calibrated by the full method."""
    table, _ = simulate_stops(seed=1, temperature_c=np.linspace(5.0, 25.0, 12))
    return table, calibrate(table)


@pytest.fixture(scope="module")
def paper_html(paper_scenario: tuple[StopTable, Calibration]) -> str:
    table, cal = paper_scenario
    return render(cal, table)


def _figure_count(html: str) -> int:
    return html.count("<figure>")


# --- content --------------------------------------------------------------------------------------


def test_report_states_every_angle_with_its_sigma(
    paper_scenario: tuple[StopTable, Calibration], paper_html: str
) -> None:
    _, cal = paper_scenario
    for est in angle_estimates(cal).values():
        assert est.determined
        assert format_pm(est.value, est.sigma) in paper_html
    assert "Cramér–Rao bound" in paper_html
    assert cal.gravity_source in paper_html
    assert f"{cal.fit.chi2:.4g} on {cal.fit.dof} degrees of freedom" in paper_html
    assert "all uncertainties 1σ" in paper_html


def test_report_gives_both_parts_of_each_sigma(paper_scenario: tuple[StopTable, Calibration], paper_html: str) -> None:
    _, cal = paper_scenario
    part = cal.systematic
    assert part is not None and part.default_spec  # no sensor limits given: the default class, said
    assert "total √(statistical² + systematic²)" in paper_html and "default class was assumed" in paper_html
    for k in ("roll_deg", "pitch_deg"):
        assert f"{part.statistical[k]:.3g}° / {part.systematic[k]:.3g}°" in paper_html
    assert ("dominated by sensor errors" in paper_html) == part.dominant


def test_report_is_self_contained(paper_html: str) -> None:
    assert "<script" not in paper_html and "<link" not in paper_html
    assert not re.search(r'(src|href)="(?!data:|#)', paper_html), "every reference must be inline"
    # 3-D stops, residual against heading, against temperature and time, uncertainty against the bound
    assert _figure_count(paper_html) == paper_html.count("<svg") >= 4
    ids = re.findall(r'\bid="([^"]+)"', paper_html)
    assert len(ids) == len(set(ids)), "figure ids must not collide in one page"


def test_report_from_the_json_alone_draws_the_residuals_and_says_what_is_missing(
    paper_scenario: tuple[StopTable, Calibration],
) -> None:
    _, cal = paper_scenario
    doc = json.loads(json.dumps(cal.to_dict()))
    html = render(Calibration.from_dict(doc))
    assert "pass the stop table (<code>table=</code>)" in html  # says why the 3-D figure is absent, in Python terms
    assert _figure_count(html) >= 2  # residual per stop, uncertainty against the bound
    with_table = render(paper_scenario[1], paper_scenario[0])
    assert _figure_count(with_table) > _figure_count(html)


def test_what_cannot_be_determined_is_said_in_words() -> None:
    table, _ = simulate_stops(seed=2, headings="none")
    cal = calibrate(table)
    assert cal.yaw_deg is None and cal.yaw_reason
    html = render(cal, table)
    assert "not determined" in html
    assert cal.yaw_reason.split(":")[0] in html


def test_paper_method_report_has_no_observability_but_renders(paper_scenario: tuple[StopTable, Calibration]) -> None:
    table, _ = paper_scenario
    cal = calibrate(table, Options(method="paper"))
    html = render(cal, table)
    assert "the paper's method" in html
    assert "Not computed for this method" in html
    assert _figure_count(html) >= 3


def test_missing_loop_entries_degrade_to_a_sentence(paper_scenario: tuple[StopTable, Calibration]) -> None:
    _, cal = paper_scenario
    doc = cal.to_dict()
    for key in ("model_steps", "unexplained", "effects", "diagnostics", "confident"):
        doc.pop(key, None)
    html = render(Calibration.from_dict(doc))
    assert "carries no model steps" in html
    assert "No analysis of unexplained residual structure" in html


def test_model_steps_and_unexplained_structure_are_rendered() -> None:
    table, _ = simulate_stops(seed=5, slope_deg=12.0, bias_mps2=BIAS_20MG)
    doc = calibrate(table).to_dict()
    assert doc["model_steps"], "the loop records at least its first step"
    found = Finding("harmonic2", "residual varying as 2β with heading", "3.1 mg RMS", 30.0, 2, 1e-6, -6.0)
    doc["unexplained"] = [found.to_dict()]
    steps = Calibration.from_dict(doc).model_steps
    html = render(Calibration.from_dict(doc), table)
    assert len(steps) == len(doc["model_steps"])
    for i, step in enumerate(steps):
        assert step_label(i, step) in html
        roll = angle_estimates(step)["roll"]
        assert format_pm(roll.value, roll.sigma) in html
    assert "residual varying as 2β with heading" in html and "3.1 mg RMS" in html
    assert "Angles with 1σ error bars" in html or _figure_count(html) >= 5


def test_a_model_step_of_another_shape_is_refused_naming_it() -> None:
    """The report reads typed steps only: a step in some other layout is no guess but a refusal."""
    table, _ = simulate_stops(seed=5, slope_deg=12.0, bias_mps2=BIAS_20MG)
    doc = calibrate(table).to_dict()
    doc["model_steps"][0] = {"terms": ["rotation", "slope"], "roll_deg": 1.0, "roll_sigma_deg": 0.1}
    with pytest.raises(InputError, match=r"model_steps\.0"):
        Calibration.from_dict(doc)


def test_a_stop_table_of_another_result_is_refused(paper_scenario: tuple[StopTable, Calibration]) -> None:
    _, cal = paper_scenario
    other, _ = simulate_stops(seed=3, beta_deg=tuple(range(0, 360, 45)))
    with pytest.raises(InputError, match="8 stops"):
        render(cal, other)


def test_a_document_that_is_not_a_result_is_refused() -> None:
    with pytest.raises(InputError, match="format"):
        Calibration.from_dict({"format": "something else"})
    with pytest.raises(TypeError, match="takes a Calibration"):  # the report takes the typed result, never a dict
        render({"format": "mountcal.calibration"})  # type: ignore[arg-type]


def test_png_figures_are_embedded_as_decodable_images(paper_scenario: tuple[StopTable, Calibration]) -> None:
    table, cal = paper_scenario
    html = render(cal, table, image_format="png")
    payloads = re.findall(r'src="data:image/png;base64,([^"]+)"', html)
    assert len(payloads) == _figure_count(html) >= 4 and "<svg" not in html
    image = mpimg.imread(io.BytesIO(base64.b64decode(payloads[0])), format="png")
    assert image.shape[0] > 200 and image.shape[1] > 400


def test_short_source_names_split_logs_by_folder() -> None:
    assert short_source("/a/b/car/0165/1.MF4 + /a/b/car/0165/2.MF4") == "car/0165 (2 files)"
    assert short_source("/x/y/stops.csv") == "y/stops.csv"


def test_embedded_svg_ids_are_prefixed_with_their_references() -> None:
    svg = '<?xml version="1.0"?>\n<svg width="10pt" height="5pt"><defs><path id="g1"/></defs><use href="#g1"/></svg>'
    out = embed_svg(svg, "fig3-", "label")
    assert out.startswith("<svg") and 'id="fig3-g1"' in out and 'href="#fig3-g1"' in out
    assert 'width="10pt"' not in out and 'aria-label="label"' in out


# --- figures --------------------------------------------------------------------------------------


def _axes_labelled_with_units(fig: Figure) -> None:
    for ax in fig.axes:
        if not ax.get_visible() or ax.get_label() == "<colorbar>":
            continue
        labels = [ax.get_xlabel(), ax.get_ylabel()]
        if hasattr(ax, "get_zlabel"):
            labels.append(ax.get_zlabel())
        for label in labels:
            if label:
                assert re.search(r"\((deg|mm/s²|mg|m/s²|°C|s|min|deg, .*)\)", label), label


def test_fitted_circle_passes_through_the_fitted_stops() -> None:
    """docs/conventions.md §2: the fitted stop positions lie on R_vsᵀ f_v(α, β) + b, the circle drawn in 3-D."""
    table, _ = simulate_stops(seed=5, slope_deg=12.0, bias_mps2=BIAS_20MG)
    cal = calibrate(table, Options(model="rotation,slope,bias"))
    on_circle = figures.fitted_circle_s(cal, table.beta_rad)  # type: ignore[arg-type]
    np.testing.assert_allclose(on_circle, table.acc_s - cal.residual_s, atol=1e-9)
    centre = figures.fitted_circle_s(cal, np.linspace(0, 2 * np.pi, 721)[:-1]).mean(axis=0)
    radius = np.linalg.norm(on_circle - centre, axis=1)
    np.testing.assert_allclose(radius, cal.gravity_mps2 * np.sin(np.radians(cal.slope_deg)), rtol=1e-9)  # type: ignore[arg-type]


def test_figures_label_units_and_show_one_sigma(paper_scenario: tuple[StopTable, Calibration]) -> None:
    table, cal = paper_scenario
    heading = figures.residual_vs_heading(cal, table)
    _axes_labelled_with_units(heading)
    ax = heading.axes[0]
    bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
    assert len(bars) == 3  # sensor x, y, z
    half_len_mm = np.abs(np.diff(bars[0].lines[2][0].get_segments(), axis=1))[:, 0, 1] / 2
    assert table.cov_s is not None
    np.testing.assert_allclose(half_len_mm, np.sqrt(table.cov_s[:, 0, 0]) * 1e3, rtol=1e-6)
    assert "heading β (deg" in ax.get_xlabel()

    for fig in (figures.stops_3d(cal, table), figures.residual_trends(cal, table), figures.uncertainty_vs_crb(cal)):
        _axes_labelled_with_units(fig)
    crb_fig = figures.uncertainty_vs_crb(cal)
    texts = [t.get_text() for t in crb_fig.axes[0].texts]
    assert f"{cal.roll_sigma_deg:.3g}°" in texts


def test_angles_figures_draw_error_bars_and_truth(paper_scenario: tuple[StopTable, Calibration]) -> None:
    table, cal = paper_scenario
    paper = calibrate(table, Options(method="paper"))
    fig = figures.angles({"paper": paper, "full": cal}, truth_deg={"roll": 5.0, "pitch": 6.0, "yaw": 7.0})
    _axes_labelled_with_units(fig)
    roll_ax = fig.axes[0]
    (bars,) = [c for c in roll_ax.containers if isinstance(c, ErrorbarContainer)]
    np.testing.assert_allclose(bars.lines[0].get_ydata(), [paper.roll_deg, cal.roll_deg])
    assert any(line.get_linestyle() == "--" for line in roll_ax.lines)  # the truth

    series = figures.angles_over_time([0.0, 1.0, 2.0], [cal, paper, cal], "days since the first log (d)", marks=[1.5])
    assert len(series.axes) == 3
    assert series.axes[-1].get_xlabel() == "days since the first log (d)"


def test_a_stop_left_out_of_the_fit_is_marked() -> None:
    disturbance = np.zeros((12, 3))
    disturbance[4] = [0.3, 0.2, -0.3]  # 50 mg: one stop that was not really still
    table, _ = simulate_stops(seed=3, slope_deg=8.0, disturbance_mps2=disturbance)
    cal = calibrate(table)
    mask = figures.excluded_stops(cal)
    if not mask.any():
        pytest.skip("this build's calibrate does not leave disturbed stops out")
    assert np.flatnonzero(mask).tolist() == [4]
    fig = figures.residual_vs_heading(cal, table)
    assert "left out of the fit" in [t.get_text() for t in fig.legends[0].get_texts()]


# --- command line ---------------------------------------------------------------------------------


@pytest.fixture
def result_files(tmp_path: Path) -> tuple[Path, Path]:
    table, _ = simulate_stops(seed=4, temperature_c=np.linspace(10.0, 20.0, 12))
    stops = tmp_path / "stops.csv"
    write_stop_table(table, stops)
    result = tmp_path / "result.json"
    assert main(["calibrate", str(stops), "-o", str(result)]) == 0
    return result, stops


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_cli_writes_the_report(result_files: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    result, stops = result_files
    before = _sha(result), _sha(stops)
    out = result.parent / "report.html"
    assert main(["report", str(result), "--stops", str(stops), "-o", str(out)]) == 0
    html = out.read_text(encoding="utf-8")
    err = capsys.readouterr().err  # the summary and the status go to stderr
    assert f"({_figure_count(html)} figures): {out}" in err.splitlines()[0] and f"mountcal: wrote {out}" in err
    assert _figure_count(html) >= 4
    assert (_sha(result), _sha(stops)) == before  # inputs untouched
    assert main(["report", str(result)]) == 0  # default output beside the result
    assert result.with_suffix(".html").is_file()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--stops", "{stops}", "-o", "{stops}"], "never overwrites its input"),
        (["-o", "{result}"], "never overwrites its input"),
        (["--stops", "{other}"], "the stop table of this result"),
        (["--stops", "{missing}"], "Check the path"),
    ],
)
def test_cli_refuses_bad_input_without_writing(
    result_files: tuple[Path, Path], capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    result, stops = result_files
    other = result.parent / "other.csv"
    write_stop_table(simulate_stops(seed=9, beta_deg=tuple(range(0, 360, 60)))[0], other)
    paths = {"stops": stops, "result": result, "other": other, "missing": result.parent / "nope.csv"}
    before = {p: _sha(p) for p in (result, stops, other)}
    out = result.parent / "out.html"
    argv = ["report", str(result), *(a.format(**paths) for a in args)]
    if "-o" not in args:
        argv += ["-o", str(out)]
    assert main(argv) != 0
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()
    assert not list(result.parent.glob(".*.part"))
    assert {p: _sha(p) for p in before} == before


@pytest.mark.invalid_results  # a version from the future, refused on purpose
def test_cli_refuses_a_json_that_is_not_a_result(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": "mountcal.calibration", "format_version": 99}), encoding="utf-8")
    assert main(["report", str(bad), "-o", str(tmp_path / "r.html")]) != 0
    assert "format_version" in capsys.readouterr().err
    assert not (tmp_path / "r.html").exists()


# --- a real headless browser ----------------------------------------------------------------------

CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-logging=stderr",
    "--v=0",
)


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    pytest.skip("no chromium binary on PATH (Debian: apt-get install -y chromium)")


def _browse(page: Path, profile: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    cmd = [_chromium(), *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *extra, page.resolve().as_uri()]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)


@pytest.mark.parametrize("image_format", ["svg", "png"])
def test_report_renders_in_headless_chromium(
    paper_scenario: tuple[StopTable, Calibration], tmp_path: Path, image_format: Any
) -> None:
    table, cal = paper_scenario
    page = tmp_path / "report.html"
    html = render(cal, table, image_format=image_format)
    page.write_text(html, encoding="utf-8")
    n_figures = _figure_count(html)

    dom = _browse(page, tmp_path / "profile-dom", "--dump-dom")
    assert dom.returncode == 0, dom.stderr[-2000:]
    tag = "<svg" if image_format == "svg" else "<img"
    assert dom.stdout.count(tag) == n_figures >= 4, "every figure must be in the rendered DOM"
    assert "Mounting angles" in dom.stdout and format_pm(cal.roll_deg, cal.roll_sigma_deg) in dom.stdout
    console = [line for line in dom.stderr.splitlines() if "CONSOLE" in line or "Uncaught" in line]
    assert console == [], "the page must log nothing to the console"

    shot = tmp_path / "report.png"
    run = _browse(page, tmp_path / "profile-shot", f"--screenshot={shot}", "--window-size=1200,2000")
    assert run.returncode == 0 and shot.is_file(), run.stderr[-2000:]
    image = mpimg.imread(shot)
    assert image.shape[:2] == (2000, 1200)
    grey = image[..., :3].mean(axis=2)
    assert np.unique(np.round(grey * 255)).size > 50, "a screenshot of a real page has many grey levels"
    assert (grey < 0.5).mean() > 0.005, "text and lines are drawn"


def test_a_report_of_a_log_renders_in_headless_chromium_with_its_stops_over_time(tmp_path: Path) -> None:
    from mountcal.calibration.pipeline import calibrate_log
    from mountcal.io.reader import LogOptions
    from mountcal.outputs.report import timeline_of

    data = Path(__file__).resolve().parents[1] / "data"
    done = calibrate_log(
        data / "parking.blf", log=LogOptions(dbc=str(data / "imu_mm5_10.dbc")), protocol=data / "parking_protocol.csv"
    )
    assert done.table is not None
    page = tmp_path / "log.html"
    html = render(done.calibration, done.table, timeline=timeline_of(done))
    page.write_text(html, encoding="utf-8")
    dom = _browse(page, tmp_path / "profile-log", "--dump-dom")
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert dom.stdout.count("<svg") == _figure_count(html) >= 5
    stops = sorted(int(n) for n in re.findall(r'\bid="fig1-stop-(\d+)"', dom.stdout))  # the first figure
    assert stops == list(range(1, len(done.table) + 1))
    console = [line for line in dom.stderr.splitlines() if "CONSOLE" in line or "Uncaught" in line]
    assert console == []
