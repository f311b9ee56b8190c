"""The scapulohumeral rhythm (exubio.scapulohumeral, exubio.rhythm, the rhythm pages): phases and
cycles, resampling that never bridges a value not measured, subject and group averages (each
subject once), the corridor in the CSV columns' own frames, the API's tables against the files
they come from, and the pages drawn. No solver: the result files are written from known angles."""
from __future__ import annotations

import json

import numpy as np
import pytest

import exubio
from exubio.io.results import read_angles_csv, write_angles_csv
from exubio.model.angles import ANATOMICAL_COLUMNS, anatomical_table, joint_angles
from exubio.model.load import load_model
from exubio.scapulohumeral.files import read_trial_rhythm, study_rhythm
from exubio.scapulohumeral.reference import ANGLE_OF, ISB_DEFINITIONS, reference, trial_plane
from exubio.scapulohumeral.table import (HT_GRID_DEG, RHYTHM_ANGLES, average, phases, resample,
                                         trial_rhythm)
from exubio.synth.simulate import simulate_trial


@pytest.fixture(scope="module")
def model():
    return load_model()


def _sim(model, motion="abduction", seed=0, duration_s=6.0):
    s = simulate_trial(model, motion, duration_s=duration_s, rate_hz=50, seed=seed)
    names, a = anatomical_table(model, s.q_true)
    return s.trajectories.time_s, names, np.degrees(a)


def test_phases_find_raising_and_lowering_runs_and_ignore_small_ones():
    t = np.arange(0, 10, 0.01)
    ht = np.interp(t, [0, 1, 4, 5, 8, 8.5, 9, 10], [10, 10, 130, 130, 10, 20, 10, 10])
    phase, cycle = phases(ht, t)
    assert phase[(t > 1.2) & (t < 3.8)].min() == 1 and phase[(t > 5.2) & (t < 7.8)].max() == 2
    assert (phase[(t > 8.05) & (t < 8.95)] == 0).all()  # a 10-deg wiggle is no cycle
    assert len(np.unique(cycle[cycle >= 0])) == 2
    assert (phase[(t > 4.2) & (t < 4.8)] == 0).all()  # holding at the top


def test_resampling_is_exact_on_a_line_and_never_bridges_what_is_not_measured():
    t = np.arange(0, 4, 0.01)
    ht = np.interp(t, [0, 2, 4], [10, 130, 10])
    names = ["HT_X_elevation", "HT_Y_plane_of_elevation", *(a for a, _ in RHYTHM_ANGLES)]
    vals = np.column_stack([-ht, np.zeros_like(t)] + [0.5 * ht + k for k in range(len(RHYTHM_ANGLES))])
    ok = np.ones(vals.shape, dtype=bool)
    gap = (ht > 60) & (ht < 80) & (t < 2)  # the first angle not measured there while raising
    ok[gap, 2] = False
    r = trial_rhythm(t, names, vals, None, ok)
    rs = resample(r)
    inside = (HT_GRID_DEG >= 20) & (HT_GRID_DEG <= 120)
    np.testing.assert_allclose(rs.values_deg[1, inside, 1], 0.5 * HT_GRID_DEG[inside] + 1, atol=1e-9)
    raising = rs.values_deg[0, :, 0]
    assert np.isnan(raising[(HT_GRID_DEG > 60) & (HT_GRID_DEG < 80)]).all()
    np.testing.assert_allclose(raising[inside & ((HT_GRID_DEG < 58) | (HT_GRID_DEG > 82))],
                               0.5 * HT_GRID_DEG[inside & ((HT_GRID_DEG < 58) | (HT_GRID_DEG > 82))], atol=1e-9)
    assert np.isfinite(rs.values_deg[1, (HT_GRID_DEG > 60) & (HT_GRID_DEG < 80), 0]).all()  # lowering measured


def test_group_counts_each_subject_once():
    shape = (2, HT_GRID_DEG.size, len(RHYTHM_ANGLES))
    a = average([np.zeros(shape), np.zeros(shape), np.zeros(shape)])  # subject A: three trials at 0
    b = average([np.full(shape, 10.0)])  # subject B: one trial at 10
    g = average([a.mean_deg, b.mean_deg])
    assert np.allclose(g.mean_deg, 5.0) and np.allclose(g.sd_deg, np.std([0, 10], ddof=1)) and (g.n == 2).all()
    assert np.isnan(b.sd_deg).all()  # one curve: no SD


def test_the_corridor_is_in_the_csv_columns_own_definitions(model):
    """ISB_DEFINITIONS decompose a posture as the angles file's columns do: the corridor drawn
    beside a column is in that column's frames and sequence."""
    s = simulate_trial(model, "scaption", duration_s=3.0, rate_hz=20, seed=1)
    names, table = anatomical_table(model, s.q_true, unwrap=False)
    for col, (joint, i) in ANGLE_OF.items():
        mine = joint_angles(model, s.q_true, ISB_DEFINITIONS[joint])[:, i]
        d = np.angle(np.exp(1j * (mine - table[:, names.index(col)])))
        assert np.abs(d).max() < 1e-9, col


def test_the_plane_is_read_off_the_raising(model):
    for motion, plane in (("abduction", "frontal"), ("flexion", "sagittal"), ("scaption", "scapular")):
        t, names, deg = _sim(model, motion)
        r = trial_rhythm(t, names, deg, None, np.ones(deg.shape, dtype=bool))
        assert trial_plane(r)[0] == plane, motion
    ref = reference(model, "frontal")
    assert any(s.startswith("Ludewig") for s, _, _ in ref.studies["ST_X_upward_rotation"])
    assert np.isfinite(ref.lo["ST_X_upward_rotation"]).any()
    assert reference(model, None, why="no raising").lo == {}


def _write_result(folder, stem, t, names, deg, measured=None, u_deg=None):
    folder.mkdir(parents=True, exist_ok=True)
    cols = [f"{n}_deg" for n in names]
    write_angles_csv(folder / f"{stem}.pf.csv", t, cols, np.radians(deg),
                     uncertainty_rad=None if u_deg is None else np.radians(u_deg))
    status = np.where(measured if measured is not None else np.ones(deg.shape, dtype=bool), 0, 2).astype(np.int8)
    np.savez(folder / f"{stem}.pf.npz", angle_status=status, metadata_json=json.dumps({"model": ""}))
    return folder / f"{stem}.pf.npz"


def test_api_trial_table_holds_the_files_values(model, tmp_path):
    t, names, deg = _sim(model)
    ok = np.ones(deg.shape, dtype=bool)
    st = names.index("ST_Z_posterior_tilt")
    ok[(t > 1.0) & (t < 1.5), st] = False
    u = np.full(deg.shape, 0.7)
    npz = _write_result(tmp_path, "abd", t, names, deg, ok, u)
    df = exubio.rhythm(npz.with_suffix(".csv"))
    assert set(df["angle"].cat.categories) == {a for a, _ in RHYTHM_ANGLES}
    assert set(df["phase"].cat.categories) == {"raising", "lowering"}
    assert df.attrs["plane"] == "frontal"
    tt, cols, rad = read_angles_csv(npz.with_suffix(".csv"))
    for name in ("ST_X_upward_rotation", "GH_phadke_X_elevation"):
        sub = df[df["angle"] == name]
        i = np.searchsorted(tt, sub["time_s"].to_numpy())
        np.testing.assert_allclose(sub["value_deg"], np.degrees(rad[i, cols.index(f"{name}_deg")]), atol=1e-9)
        np.testing.assert_allclose(sub["ht_elevation_deg"], -np.degrees(rad[i, cols.index("HT_X_elevation_deg")]),
                                   atol=1e-9)
    tilt = df[df["angle"] == "ST_Z_posterior_tilt"]
    assert not tilt[(tilt.time_s > 1.0) & (tilt.time_s < 1.5)]["measured"].any()
    assert np.allclose(df["u_deg"], 0.7, atol=1e-6)
    raising = df[(df["phase"] == "raising") & (df["angle"] == "ST_X_upward_rotation")]
    for _, c in raising.groupby("cycle"):
        assert np.all(np.diff(c["ht_elevation_deg"].to_numpy()) > -1.0)
    inside = df["corridor_lo_deg"].notna()
    assert inside.any() and (df.loc[inside, "corridor_lo_deg"] <= df.loc[inside, "corridor_hi_deg"]).all()


def _study(tmp_path, model, plan):
    rows = []
    for subject, seeds in plan.items():
        for seed in seeds:
            t, names, deg = _sim(model, seed=seed)
            deg = deg + seed * 0.5  # each trial its own offset
            folder = tmp_path / subject / "s1" / f"abd{seed}"
            _write_result(folder, f"abd{seed}", t, names, deg)
            rows.append({"subject": subject, "session": "s1", "trial": f"abd{seed}.c3d", "folder": str(folder),
                         "pf_verdict": "ok", "status": "done"})
    (tmp_path / "study.json").write_text(json.dumps({"study": "x", "trials": rows}), encoding="utf-8")
    return names


def test_api_study_table_is_the_mean_of_subject_means(model, tmp_path):
    plan = {"A": [0, 1, 2], "B": [3]}
    _study(tmp_path, model, plan)
    df = exubio.rhythm(tmp_path)
    name, h = "ST_X_upward_rotation", 60.0
    by_trial = {}
    for subject, seeds in plan.items():
        for seed in seeds:
            r = read_trial_rhythm(tmp_path / subject / "s1" / f"abd{seed}" / f"abd{seed}.pf.npz")
            sel = r.phase == 1
            o = np.argsort(r.ht_deg[sel])
            by_trial.setdefault(subject, []).append(
                np.interp(h, r.ht_deg[sel][o], r.values_deg[sel, r.names.index(name)][o]))
    subject_means = {s: np.mean(v) for s, v in by_trial.items()}
    row = df[(df.level == "group") & (df.phase == "raising") & (df.angle == name) & (df.ht_elevation_deg == h)]
    assert len(row) == 1
    assert row["mean_deg"].iloc[0] == pytest.approx(np.mean(list(subject_means.values())), abs=1e-6)
    assert row["n"].iloc[0] == 2
    a = df[(df.level == "subject") & (df.subject == "A") & (df.phase == "raising") & (df.angle == name)
           & (df.ht_elevation_deg == h)]
    assert a["mean_deg"].iloc[0] == pytest.approx(subject_means["A"], abs=1e-6)
    assert a["sd_deg"].iloc[0] == pytest.approx(np.std(by_trial["A"], ddof=1), abs=1e-6)


def test_study_pages_and_trial_page_are_drawn(model, tmp_path):
    from exubio.report.rhythm_page import study_rhythm_pages, trial_rhythm_figure

    _study(tmp_path, model, {"A": [0, 1], "B": [2]})
    groups = study_rhythm(tmp_path)
    assert [(g.method, g.plane) for g in groups] == [("pf", "frontal")]
    pages = study_rhythm_pages(groups, "x")
    assert len(pages) == 1 + 2  # the group, then each subject
    texts = " ".join(t.get_text() for t in pages[0].texts)
    assert "2 subjects, 3 trials" in texts and "Ludewig" in texts
    fig = trial_rhythm_figure(tmp_path / "A" / "s1" / "abd0" / "abd0.pf.npz", "abd0", "pf")
    assert fig is not None and len(fig.axes) == 8
    assert fig.axes[0].get_title() == "ST upward rotation (deg)"
    assert "upward" in fig.axes[0].get_ylabel()


def test_a_trial_without_a_raise_has_no_rhythm_page(model, tmp_path):
    from exubio.report.rhythm_page import trial_rhythm_figure

    t = np.arange(0, 4, 0.02)
    deg = np.zeros((t.size, len(ANATOMICAL_COLUMNS)))
    deg[:, ANATOMICAL_COLUMNS.index("HT_X_elevation")] = -20.0
    npz = _write_result(tmp_path, "still", t, ANATOMICAL_COLUMNS, deg)
    assert trial_rhythm_figure(npz, "still", "pf") is None
    with pytest.raises(exubio.InputError, match="study.json"):
        exubio.rhythm(tmp_path / "nothing_here")


def test_rhythm_page_drawn_into_a_reused_figure_is_that_of_a_new_figure(model, tmp_path):
    """The trial report keeps its rhythm page for the next trial of the process (as its other plot
    pages, exubio.report.page_figures): drawn again, the page is byte for byte a new figure's."""
    import io
    import re

    from exubio.report import page_figures
    from exubio.report.rhythm_page import trial_rhythm_figure

    _study(tmp_path, model, {"A": [0, 1], "B": [2]})
    npz = {s: tmp_path / p / "s1" / f"abd{s}" / f"abd{s}.pf.npz" for s, p in ((0, "A"), (1, "A"), (2, "B"))}

    def pdf(seed) -> bytes:
        fig = trial_rhythm_figure(npz[seed], f"abd{seed}", "pf")
        buf = io.BytesIO()
        fig.savefig(buf, format="pdf")
        page_figures._release(fig)
        return re.sub(rb"/CreationDate \(D:[0-9Z'+-]+\)", b"", buf.getvalue())

    fresh = {}
    for seed in npz:
        page_figures._FREE_PAGES.clear()
        fresh[seed] = pdf(seed)
    page_figures._FREE_PAGES.clear()
    for seed in [0, 1, 2, 2, 0, 1]:
        assert pdf(seed) == fresh[seed], seed
    assert len(page_figures._FREE_PAGES[("rhythm",)]) == 1  # one figure drawn into again, not one per page
    assert fresh[0] != fresh[1]  # the pages differ: the comparison can fail


def test_study_pages_drawn_into_one_reused_figure_are_those_of_new_figures(model, tmp_path):
    """The study report draws its rhythm pages one at a time into one figure (each_study_rhythm_page
    with reuse): every page is byte for byte the page a new figure gives, whatever page came before."""
    import io
    import re

    from exubio.report import page_figures
    from exubio.report.rhythm_page import each_study_rhythm_page, study_rhythm_pages

    _study(tmp_path, model, {"A": [0, 1], "B": [2]})
    groups = study_rhythm(tmp_path)

    def pdf(fig) -> bytes:
        buf = io.BytesIO()
        fig.savefig(buf, format="pdf")
        return re.sub(rb"/CreationDate \(D:[0-9Z'+-]+\)", b"", buf.getvalue())

    fresh = [pdf(f) for f in study_rhythm_pages(groups, "x")]
    assert len(fresh) == 3 and len(set(fresh)) == 3  # the group and two subjects: the pages differ
    page_figures._FREE_PAGES.clear()
    for _ in range(2):  # the second time, the first page too is drawn into a used figure
        figs, pages = [], []
        for f in each_study_rhythm_page(groups, "x", reuse=True):
            figs.append(f)
            pages.append(pdf(f))
        assert pages == fresh
        assert len({id(f) for f in figs}) == 1  # one figure for every page
