"""The report a researcher reads (issue 31): a section per input that its metrics row links to, the wheel's
parameters with their sources, the provenance (version, command, wheel file, inputs by name and hash), step
periods grouped by series (never pooled across series by rounded slope), a metrics table that fits a 1280 px
window, and no absolute path of the machine in the page, the CSV or the figures' metadata.

The expectations are computed apart from the report: hashes with hashlib from the files' bytes, the wheel file's
values from the TOML this test writes, step periods from the importer, the parameter list from the model's
field list, HTML read back with the stdlib parser."""

from __future__ import annotations

import csv
import hashlib
import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import rimless
from rimless.analysis.examples.bundled import data_files
from rimless.analysis.examples.critical_series import data_files as critical_files
from rimless.analysis.inference.compare import Simulator
from rimless.analysis.kinematics.build import import_trial
from rimless.analysis.report.html import build_report
from rimless.cli import app as root_app

runner = CliRunner()
GAP = {"max_gap_s": 0.05}


class _Page(HTMLParser):
    """Ids, links, images, sections, and the cells of every table by its id."""

    def __init__(self) -> None:
        super().__init__()
        self.ids: list[str] = []
        self.links: list[str] = []
        self.imgs: list[str] = []
        self.sections: list[str] = []
        self.tables: dict[str, list[list[dict]]] = {}
        self._table: list[str | None] = []
        self._cell: dict | None = None
        self._classes: list[str] = []
        self._section: str | None = None
        self.section_text: dict[str, str] = {}
        self.section_imgs: dict[str, list[str]] = {}

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.append(a["id"])
        if tag == "a" and "href" in a:
            self.links.append(a["href"])
            if self._cell is not None:
                self._cell["href"] = a["href"]
        if tag == "img":
            self.imgs.append(a["src"])
            if self._section:
                self.section_imgs[self._section].append(a["src"])
        if tag == "section":
            self._section = a.get("id")
            self.sections.append(a.get("id"))
            self.section_text[self._section] = ""
            self.section_imgs[self._section] = []
        if tag == "table":
            self._table.append(a.get("id"))
            if a.get("id"):
                self.tables[a["id"]] = []
        if tag == "tr" and self._table and self._table[-1]:
            self.tables[self._table[-1]].append([])
        if tag in ("td", "th") and self._table and self._table[-1]:
            self._cell = {"tag": tag, "text": "", "class": a.get("class") or "", "attrs": a, "breaks": []}
            self.tables[self._table[-1]][-1].append(self._cell)
        if tag == "br" and self._cell is not None:
            self._cell["text"] += "\n"
        if tag == "wbr" and self._cell is not None:
            self._cell["breaks"].append(len(self._cell["text"]))

    def handle_endtag(self, tag):
        if tag == "table" and self._table:
            self._table.pop()
        if tag in ("td", "th"):
            self._cell = None
        if tag == "section":
            self._section = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell["text"] += data
        if self._section:
            self.section_text[self._section] += data


def _page(path: Path) -> _Page:
    p = _Page()
    p.feed(path.read_text(encoding="utf-8"))
    return p


@pytest.fixture(scope="module")
def sim():
    return Simulator()


@pytest.fixture(scope="module")
def built(tmp_path_factory, sim):
    """A report on: two ER trials and one of the critical series (copied under absolute paths in a tmp folder,
    so that any absolute path leaking into the report would name it), a Parquet trial, a refused file, and a
    wheel file with k and m_H given."""
    root = tmp_path_factory.mktemp("abs-root-marker")
    src = root / "lab data"
    src.mkdir()
    er = [shutil.copy(f, src / f.name) for f in data_files()[:2]]
    crit = shutil.copy(critical_files()[8], src / critical_files()[8].name)
    pq = import_trial(data_files()[2], **GAP).to_parquet(src / "third.trial.parquet")
    bad = src / "bad.csv"
    bad.write_text("Objects\n100\n,,Global Angle W:W\nFrame,Sub Frame,RX\n,,rad\n1,0,abc\n")
    wheel = root / "my wheel.toml"
    wheel.write_text("[wheel]\nm_H = 1.95\nk = {value = 3000, sd = 200}\nc = {sd = 3}\n")
    from rimless.analysis.inference.runs import wheel_input

    win = wheel_input(wheel)
    files = [Path(er[0]), Path(er[1]), Path(crit), pq, bad]
    res = build_report(
        files, root / "rep", sim=sim.__class__(params=win.params), import_kwargs=GAP, wheel_input=win, critical=False
    )
    return {"res": res, "root": root, "files": files, "wheel": wheel, "page": _page(res.report_html)}


def test_every_input_has_a_section_that_its_metrics_row_links_to(built):
    res, page, files = built["res"], built["page"], built["files"]
    for href in page.links:  # every link on the page resolves: an anchor on it, or a file beside it
        if href.startswith("#"):
            assert href[1:] in page.ids, href
        else:
            assert (res.out_dir / href).is_file(), href
    assert len(page.sections) == len(files) == len(set(page.sections))
    rows = [r for r in page.tables["metrics"][1:]]
    assert len(rows) == len(files)
    for f, row, section in zip(files, rows, page.sections):
        assert row[0]["text"] == f.name and row[0]["href"] == f"#{section}"
        assert f.name in page.section_text[section]
    by_name = {Path(r.file).name: r for r in res.inputs}
    for f, section in zip(files, page.sections):
        text = page.section_text[section]
        row = by_name[f.name]
        if row.trial is None:  # the refused file: its reason, by name, and no figure
            assert "bad.csv" in text and "line 6" in text and not page.section_imgs[section]
            continue
        m = row.trial.meta
        assert f"{m.slope_deg:.3f} deg from {m.slope_source}" in text  # the slope and its source
        for note in row.warnings:  # the importer's notes, each
            assert note.split(built["root"].name)[0] in text
        (img,) = page.section_imgs[section]  # its own figure: CoM height and step periods
        assert (res.out_dir / img).stat().st_size > 5000
        assert img != "com_height.png"
    # the sections' figures are distinct files
    imgs = [i for s in page.sections for i in page.section_imgs[s]]
    assert len(imgs) == len(set(imgs)) == len(files) - 1


def test_no_absolute_path_in_the_page_the_csv_or_the_figures(built):
    res, root = built["res"], built["root"]
    forbidden = {str(root), str(root.resolve()), root.name, str(Path.home()) + "/", str(Path.cwd()) + "/"}
    forbidden.discard("/")
    texts = {res.report_html: res.report_html.read_text(encoding="utf-8")}
    texts[res.metrics_csv] = res.metrics_csv.read_text(encoding="utf-8")
    from PIL import Image

    for png in res.out_dir.glob("*.png"):
        with Image.open(png) as im:
            texts[png] = json.dumps({k: str(v) for k, v in im.info.items()}) + json.dumps(getattr(im, "text", {}))
    for path, text in texts.items():
        for bad in forbidden:
            assert bad not in text, (path.name, bad)
        assert not re.search(r"(?<![\w.:/~-])/(?:tmp|home|root|Users|var|private)/", text), path.name
    # the CSV names each input by its name; the refusal reason is still there, by name
    with open(res.metrics_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["file"] for r in rows[:3]] == [f.name for f in built["files"][:3]]
    assert "bad.csv" in rows[-1]["message"] and "line 6" in rows[-1]["message"]


def test_the_parameter_table_lists_every_parameter_with_its_source(built):
    from rimless.sim.model.uncertain import UNCERTAIN_FIELDS

    rows = built["page"].tables["parameters"][1:]
    held = [r for r in rows if "held" in (r[0]["attrs"].get("class") or "")] or rows
    got = {r[0]["text"].split()[1]: r for r in held}  # the field name after the symbol
    assert sorted(got) == sorted(UNCERTAIN_FIELDS)
    source = {n: r[4]["attrs"]["data-source"] for n, r in got.items()}
    # from the TOML written above: m_H exact, k 3000 +- 200, c Table 1's value with sd 3, the rest Table 1
    assert source["hub_mass_kg"] == "wheel_file" and got["hub_mass_kg"][2]["text"] == "exact"
    assert float(got["hub_mass_kg"][1]["text"]) == 1.95
    assert source["stiffness_n_per_m"] == "wheel_file" and float(got["stiffness_n_per_m"][1]["text"]) == 3000
    assert float(got["stiffness_n_per_m"][2]["text"]) == 200
    assert float(got["damping_ns_per_m"][2]["text"]) == 3
    assert source["inertia_kg_m2"] == source["gravity_m_s2"] == "table1"
    assert got["stiffness_n_per_m"][4]["text"] == "wheel file" and got["inertia_kg_m2"][4]["text"] == "Table 1"
    # the basis names the wheel file by name, never by its folder
    assert "my wheel.toml" in got["stiffness_n_per_m"][5]["text"]
    assert str(built["root"]) not in got["stiffness_n_per_m"][5]["text"]


def test_provenance_names_version_command_wheel_file_and_each_input_by_hash(built):
    res, page = built["res"], built["page"]
    facts = {r[0]["text"]: r[1]["text"] for r in page.tables["provenance-facts"]}
    assert facts["rimless"] == rimless.__version__
    assert facts["command"].startswith("Python API: ")
    assert facts["wheel file"] == "my wheel.toml"
    assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", facts["date"])
    listed = {(r[0]["text"], r[1]["text"]): r[3]["text"] for r in page.tables["input-files"][1:]}
    for f in built["files"]:
        assert listed[("trial", f.name)] == hashlib.sha256(f.read_bytes()).hexdigest()
    assert listed[("wheel file", "my wheel.toml")] == hashlib.sha256(built["wheel"].read_bytes()).hexdigest()
    assert res.summary()["provenance"]["rimless_version"] == rimless.__version__


def test_the_command_line_is_in_the_report_without_its_folders(tmp_path):
    data = tmp_path / "abs-data"
    data.mkdir()
    f = shutil.copy(data_files()[0], data / data_files()[0].name)
    out = tmp_path / "out"
    res = runner.invoke(root_app, ["trials", "report", str(f), "--out", str(out), "--slope-bin-deg", "0.25"])
    assert res.exit_code == 0, res.output
    page = _page(out / "report.html")
    facts = {r[0]["text"]: r[1]["text"] for r in page.tables["provenance-facts"]}
    assert facts["command"] == f"rimless trials report {Path(f).name} --out out --slope-bin-deg 0.25"
    assert str(tmp_path) not in (out / "report.html").read_text(encoding="utf-8")


def test_series_names_from_file_names():
    from rimless.analysis.report.series import series_name

    # hand-made cases: what varies from run to run goes, the wheel and set-up stay
    assert series_name("SYNTHETIC_er_slope2.0deg_run2.csv") == "SYNTHETIC_er"
    assert series_name("SYNTHETIC_crit_slope1.90deg_release1.9.csv") == "SYNTHETIC_crit"
    assert series_name("/data/wheelB-1.5deg-take03.c3d") == "wheelB"
    assert series_name("stiff wheel 2deg 4.trial.parquet") == "stiff wheel"
    assert series_name("/lab/monday/run1.csv") == "monday"  # nothing left: the folder's name


def test_step_periods_are_grouped_by_series_never_pooled_across_series(tmp_path, sim):
    """Two series whose slopes round to the same 0.5 deg bin (2.0 deg: the Table 1 wheel's trials at 1.99 deg;
    1.90 deg: the critical series' wheel, c = 10 N s/m and guide friction) stay two groups; each group's mean
    period is its own trials' mean, from the importer."""
    er = [shutil.copy(f, tmp_path / f"wheelA_{f.name.split('_', 2)[2]}") for f in data_files()[2:4]]
    crit = [shutil.copy(critical_files()[8], tmp_path / "wheelB_slope1.90deg_run1.csv")]
    files = [Path(p) for p in er + crit]
    res = build_report(files, tmp_path / "rep", sim=sim, import_kwargs=GAP, critical=False)
    groups = {(g.series, g.slope_deg): g for g in res.groups}
    assert set(groups) == {("wheelA", 2.0), ("wheelB", 2.0)}
    for series, members in (("wheelA", files[:2]), ("wheelB", files[2:])):
        g = groups[(series, 2.0)]
        assert sorted(g.trials) == sorted(f.name for f in members)
        by_step: dict[int, list[float]] = {}  # the importer's periods by step number (a gap keeps the numbering)
        for f in members:
            t = import_trial(f, **GAP)
            steps = np.asarray(t.meta.period_step or range(1, t.step_period_s.size + 1))
            for k, period in zip(steps - steps[0] + 1, t.step_period_s):
                by_step.setdefault(int(k), []).append(float(period))
        assert list(g.step_number) == sorted(by_step)
        np.testing.assert_allclose(g.mean_period_s, [np.mean(by_step[k]) for k in sorted(by_step)], rtol=1e-12)
        np.testing.assert_array_equal(g.count, [len(by_step[k]) for k in sorted(by_step)])
    rows = res.summary()["step_period_by_slope"]
    assert {r["series"] for r in rows} == {"wheelA", "wheelB"}
    table = _page(res.report_html).tables["periods"]
    assert table[0][0]["text"] == "series" and {r[0]["text"] for r in table[1:]} == {"wheelA", "wheelB"}
    with open(res.metrics_csv, newline="") as fh:
        assert [r["series"] for r in csv.DictReader(fh)] == ["wheelA", "wheelA", "wheelB"]


# A table fits a 1280 px window when its narrowest layout does. Assumptions (the page's CSS: body 16 px, tables
# at .85em = 13.6 px; padding .5em a side and a 1 px border): a character at most 0.62 em wide (system-ui and
# DejaVu Sans digits are 0.55-0.64 em; bold headers included), so 8.4 px; 14.6 px of padding and border per
# column; the page's content box at a 1280 px window is min(1280, 1200) - 2 * 16 = 1168 px. A number never
# wraps (its whole length counts); a header wraps between words (its longest word counts); a trial name breaks
# only at its <wbr> (its longest piece counts).
CHAR_PX, COLUMN_PX, CONTENT_PX = 13.6 * 0.62, 14.6, 1168


def _narrowest_px(table: list[list[dict]]) -> float:
    widths: dict[int, int] = {}
    for row in table:
        for j, cell in enumerate(row):
            text = cell["text"]
            if cell["tag"] == "th":
                need = max(len(w) for w in text.split())
            elif "n" in cell["class"].split():
                need = len(text)  # nowrap
            else:
                cuts = [0, *cell["breaks"], len(text)]
                need = max(max(len(w) for w in text[a:b].split() or [""]) for a, b in zip(cuts, cuts[1:]))
            widths[j] = max(widths.get(j, 0), need)
    return sum(w * CHAR_PX + COLUMN_PX for w in widths.values())


def test_the_metrics_tables_fit_1280_px_and_numbers_never_wrap(tmp_path, sim):
    # the demo's longest names, under longer absolute folders
    names = [f.name for f in critical_files()[:2]] + [data_files()[0].name]
    files = [Path(shutil.copy(f, tmp_path / f.name)) for f in critical_files()[:2] + data_files()[:1]]
    assert [f.name for f in files] == names
    res = build_report(files, tmp_path / "rep", sim=sim, import_kwargs=GAP, critical=False)
    page = _page(res.report_html)
    css = res.report_html.read_text(encoding="utf-8")
    assert re.search(r"td\.n\{[^}]*white-space:nowrap", css)  # numbers never wrap
    assert re.search(r"\.wide\{[^}]*overflow-x:auto", css)  # a table too wide scrolls in its wrapper
    for tid in ("metrics", "fitted"):
        table = page.tables[tid]
        assert len(table[0]) <= 9, [c["text"] for c in table[0]]  # split: no table of more than 9 columns
        assert all(len(row) == len(table[0]) for row in table)
        assert _narrowest_px(table) <= CONTENT_PX, (tid, _narrowest_px(table))
        assert max(len(w) for c in table[0] for w in c["text"].split()) <= 12  # no header wider than needed
        for row in table[1:]:
            for cell in row[1:]:
                if cell["text"] not in ("", "–") and re.fullmatch(r"[+-]?\d+(\.\d+)?", cell["text"]):
                    assert "n" in cell["class"].split(), cell  # every number in a nowrap cell
        headers = " ".join(c["text"] for c in table[0])
        assert all(u in headers for u in (("deg", "mm", "ms") if tid == "metrics" else ("rad/s", "ms", "mm")))
    # a name breaks after '_' or '-' only, never inside a number such as 1.9
    first = page.tables["metrics"][1][0]
    assert all(first["text"][i - 1] in "_-" for i in first["breaks"])


def test_a_report_from_python_names_the_function(tmp_path):
    from rimless.analysis import write_report

    res = write_report([data_files()[0]], tmp_path / "rep", max_gap_s=0.05)
    facts = {r[0]["text"]: r[1]["text"] for r in _page(res.report_html).tables["provenance-facts"]}
    assert facts["command"] == "Python API: rimless.analysis.write_report"
    assert facts["wheel file"].startswith("none")  # Table 1, said so
    assert res.summary()["provenance"]["command"] == facts["command"]


def _chi2_by_hand(measured: np.ndarray, simulated: np.ndarray, impact_sd_s: float) -> float:
    """Periods 2..N's chi-square with impact-time errors of sd ``impact_sd_s`` (independent impacts; a period is the
    difference of two, consecutive periods share one): written apart from `compare.period_misfit`, from the
    impacts' covariance propagated through the differencing matrix."""
    n = measured.size
    diff = np.zeros((n - 1, n))  # periods 2..n from impacts 1..n (impact 0 only enters period 1)
    for i in range(n - 1):
        diff[i, i], diff[i, i + 1] = -1.0, 1.0
    cov = impact_sd_s**2 * diff @ diff.T
    r = simulated[1:] - measured[1:]
    return float(r @ np.linalg.solve(cov, r))


def test_the_metrics_row_has_the_period_misfit_figures(built):
    """The plausibility check's figures on the step periods after the first (`compare.period_misfit`) in each compared
    trial's row of metrics.csv, of the JSON and of the report's period-fit table; the columns that were there keep
    their order in front (new columns are added at the end). Expected values: the chi-square recomputed here from the
    row's own impact noise and the comparison's periods; p from scipy's chi-square tail."""
    from scipy.stats import chi2

    res, page = built["res"], built["page"]
    old = [
        "trial", "file", "status", "slope_deg", "slope_source", "model", "steps", "rms_com_error_mm",
        "mean_abs_period_error_ms", "rms_com_relative", "com_correlation", "theta_dot_plus_rad_s",
        "release_theta_dot_rad_s", "time_shift_ms", "height_offset_mm", "message", "series",
    ]  # fmt: skip
    new = [
        "period_misfit_chi2", "period_misfit_dof", "period_misfit_p", "period_misfit_relative_rms",
        "period_misfit_impact_sd_ms", "period_misfit_noise_source",
    ]  # fmt: skip
    with open(res.metrics_csv, newline="") as fh:
        reader = csv.DictReader(fh)
        assert reader.fieldnames == old + new
        rows = list(reader)
    compared = [c for c in res.comparisons if c.status in ("ok", "suspect") and c.n_steps >= 2]
    assert len(compared) >= 3
    by_name = {r["trial"]: r for r in rows}
    table = {r[0]["text"]: r for r in page.tables["period-fit"][1:]}
    assert [c["text"] for c in page.tables["period-fit"][0]] == [
        "trial", "periods χ²", "dof", "p", "rms miss / period", "impact noise, ms"
    ]  # fmt: skip
    for c in compared:
        row = by_name[c.name]
        sd_s = float(row["period_misfit_impact_sd_ms"]) * 1e-3
        assert sd_s >= 0.3e-3 / np.sqrt(2) * (1 - 1e-5)  # never below the importer's floor (0.3 ms a period)
        use = np.isfinite(c.sim_period_s)
        assert use.all(), c.name  # these trials are simulated throughout (else the hand count below differs)
        assert c.measured_step.size == 0 or list(c.measured_step) == list(range(1, c.n_steps + 1))  # no gap
        expect = _chi2_by_hand(c.measured_period_s, c.sim_period_s, sd_s)
        assert float(row["period_misfit_chi2"]) == pytest.approx(expect, rel=1e-4)
        assert int(row["period_misfit_dof"]) == c.n_steps - 1
        assert float(row["period_misfit_p"]) == pytest.approx(chi2.sf(expect, c.n_steps - 1), rel=1e-3, abs=1e-12)
        rms = np.sqrt(np.mean((c.sim_period_s[1:] - c.measured_period_s[1:]) ** 2)) / np.median(c.measured_period_s)
        assert float(row["period_misfit_relative_rms"]) == pytest.approx(rms, rel=1e-4)
        assert row["period_misfit_noise_source"]
        cells = table[c.name]
        assert cells[2]["text"] == row["period_misfit_dof"] and "n" in cells[1]["class"].split()
        js = c.metrics()
        assert js["period_misfit_chi2"] == pytest.approx(expect, rel=1e-4)  # the CSV rounds the sd to 6 digits
    # a refused input has its row, with the figures empty
    assert all(rows[-1][k] == "" for k in new)
    # the period-fit table fits a 1280 px window like the others
    assert _narrowest_px(page.tables["period-fit"]) <= CONTENT_PX
