"""The sign switch (exubio.model.signs, ``--signs isb|clinical``): a simulated arm abduction with a
known truth reconstructed in both conventions; every output (CSV, .mot, .npz, summary.json, the
DataFrame, the report's numbers, the rhythm table, the study table) gives, for an angle and a
frame, clinical = sign x isb with the sign of an expectation written here by hand, and the raised
arm's HT elevation (the truth's angle between humerus and thorax vertical) positive in clinical,
negative in raw ISB. The protocol's ``signs`` key, the CLI over it, bad values (exit 2 naming the
key)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import exubio
from exubio.cli import main
from exubio.io.results import read_angles_csv, read_mot, read_npz_arrays, read_npz_metadata
from exubio.model.angles import ANATOMICAL_COLUMNS, humerothoracic_elevation
from exubio.model.signs import CLINICAL_FLIPPED, convert, factors

pytestmark = pytest.mark.exudyn

# Written by hand from the ISB recommendations (Wu et al. 2005) and exubio.model.angles' signs: the
# angles whose raw ISB value is negative for the motion the column names (elevation, upward
# rotation, abduction); every other one already names its positive direction.
EXPECTED_FLIPPED = {"SC_X_elevation", "AC_X_upward_rotation", "ST_X_upward_rotation", "GH_X_elevation",
                    "GH_phadke_X_elevation", "HT_X_elevation"}


def _sign(name: str) -> float:
    return -1.0 if name.removesuffix("_deg") in EXPECTED_FLIPPED else 1.0


def test_the_sign_table_is_the_expected_one_and_an_involution():
    assert set(CLINICAL_FLIPPED) == EXPECTED_FLIPPED and EXPECTED_FLIPPED <= set(ANATOMICAL_COLUMNS)
    np.testing.assert_array_equal(factors(ANATOMICAL_COLUMNS, "clinical"), [_sign(n) for n in ANATOMICAL_COLUMNS])
    np.testing.assert_array_equal(factors(ANATOMICAL_COLUMNS, "isb"), np.ones(len(ANATOMICAL_COLUMNS)))
    v = np.random.default_rng(0).normal(size=(5, len(ANATOMICAL_COLUMNS)))
    np.testing.assert_array_equal(convert(ANATOMICAL_COLUMNS, convert(ANATOMICAL_COLUMNS, v, "isb", "clinical"),
                                          "clinical", "isb"), v)
    with pytest.raises(exubio.InputError, match="signs"):
        factors(ANATOMICAL_COLUMNS, "positive")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One simulated abduction (known truth) reconstructed by LS with --signs isb and --signs clinical."""
    root = tmp_path_factory.mktemp("signs")
    model = exubio.load_model()
    sim = exubio.simulate("abduction", model, duration_s=3.0, rate_hz=50.0, noise_mm=0.3, seed=3)
    from exubio.io.c3d import write_c3d

    c3d = write_c3d(root / "abd.c3d", sim.trajectories)
    out = {}
    for signs in ("isb", "clinical"):
        assert main(["-q", "reconstruct", str(c3d), "--method", "ls", "--signs", signs, "--out", str(root / signs)]) == 0
        out[signs] = root / signs
    truth_ht = np.degrees(humerothoracic_elevation(model, sim.q_true))  # >= 0: humerus axis to thorax vertical
    return {"root": root, "c3d": c3d, "dirs": out, "truth_ht_deg": truth_ht, "sim": sim, "model": model}


def _csv(folder: Path):
    t, names, values, u = read_angles_csv(folder / "abd.ls.csv", uncertainty=True)
    return t, [n.removesuffix("_deg") for n in names], np.degrees(values), np.degrees(u)


def test_raised_arm_is_positive_in_clinical_and_negative_in_isb_against_the_truth(runs):
    peak = int(np.argmax(runs["truth_ht_deg"]))
    assert runs["truth_ht_deg"][peak] > 60.0  # the arm is raised
    for signs, sign in (("isb", -1.0), ("clinical", 1.0)):
        _, names, deg, _ = _csv(runs["dirs"][signs])
        ht = deg[:, names.index("HT_X_elevation")]
        assert abs(ht[peak] - sign * runs["truth_ht_deg"][peak]) < 2.0, (signs, ht[peak], runs["truth_ht_deg"][peak])
        assert np.sign(deg[peak, names.index("ST_X_upward_rotation")]) == sign  # the scapula rotates upward


def test_every_file_gives_the_same_value_in_both_conventions(runs):
    t_i, names, isb, u_i = _csv(runs["dirs"]["isb"])
    t_c, names_c, cli, u_c = _csv(runs["dirs"]["clinical"])
    assert names == names_c and np.array_equal(t_i, t_c)
    expect = np.array([_sign(n) for n in names])
    np.testing.assert_allclose(cli, isb * expect, atol=2e-6)  # clinical = sign x isb (CSV's 6 decimals)
    np.testing.assert_array_equal(u_i, u_c)  # an uncertainty has no sign
    for signs, deg in (("isb", isb), ("clinical", cli)):
        folder = runs["dirs"][signs]
        _, mot_names, mot = read_mot(folder / "abd.ls.mot")
        assert list(mot_names[:len(names)]) == names  # then the thorax's six free-joint columns (no sign switch)
        assert all(n.startswith("thorax_") for n in mot_names[len(names):])
        np.testing.assert_allclose(np.degrees(mot[:, :len(names)]), deg, atol=2e-6)
        mot_text = (folder / "abd.ls.mot").read_text(encoding="utf-8")
        assert f"exubio_signs={signs} " in mot_text.split("endheader")[0]
        arrays = read_npz_arrays(folder / "abd.ls.npz", ("angle_signs", "angle_names"))
        assert list(arrays["angle_names"]) == names
        np.testing.assert_array_equal(arrays["angle_signs"], expect if signs == "clinical" else np.ones(len(names)))
        assert read_npz_metadata(folder / "abd.ls.npz")["signs"] == signs
        summary = json.loads((folder / "abd.ls.summary.json").read_text(encoding="utf-8"))
        assert summary["signs"] == signs
        meaning = summary["angles"]["definitions"]["HT_X_elevation"]["meaning"]
        assert meaning.startswith("+ elevation" if signs == "clinical" else "- elevation")
        head = [line for line in (folder / "abd.ls.csv").read_text(encoding="utf-8").splitlines() if line.startswith("#")]
        assert f"# signs: {signs} " in "\n".join(head) + " "
        col = next(line for line in head if line.startswith("# HT_X_elevation:"))  # each column's positive direction
        assert col.endswith("+ elevation" if signs == "clinical" else "- elevation")
        # the npz's model coordinates (ISB inside) times its angle_signs are the CSV's angles
        from exubio.io.results import read_npz
        from exubio.model.angles import anatomical_table

        rec = read_npz(folder / "abd.ls.npz", points=False)
        _, table = anatomical_table(runs["model"], rec.q_rad)
        np.testing.assert_allclose(np.degrees(table) * arrays["angle_signs"], deg, atol=2e-6)


def test_report_numbers_and_rhythm_table_agree_with_the_csv(runs):
    from exubio.report.trial_report import read_angles

    for signs in ("isb", "clinical"):
        folder = runs["dirs"][signs]
        t, names, deg, _ = _csv(folder)
        a = read_angles(folder / "abd.ls.npz")
        assert a.signs == signs
        for name in ("HT_X_elevation", "ST_X_upward_rotation", "SC_Y_protraction"):
            j = a.names.index(name)
            np.testing.assert_allclose(a.shown_deg(j), deg[:, names.index(name)], atol=1e-9)  # what page 1 draws
        rhythm = exubio.rhythm(folder / "abd.ls.npz")
        assert rhythm.attrs["signs"] == signs
        st = rhythm[rhythm["angle"] == "ST_X_upward_rotation"]
        assert len(st) > 10
        frame = np.searchsorted(t, st["time_s"].to_numpy())
        np.testing.assert_allclose(st["value_deg"].to_numpy(), deg[frame, names.index("ST_X_upward_rotation")], atol=1e-6)
        ht = np.where(rhythm["angle"] == "ST_X_upward_rotation")[0]
        assert (rhythm["ht_elevation_deg"].to_numpy()[ht] >= 0).all()  # the x axis is positive in both
    # the corridor flips with the angle: clinical (lo, hi) = -(hi, lo) of ISB at the same HT elevation
    r_i = exubio.rhythm(runs["dirs"]["isb"] / "abd.ls.npz")
    r_c = exubio.rhythm(runs["dirs"]["clinical"] / "abd.ls.npz")
    sel = (r_i["angle"] == "ST_X_upward_rotation").to_numpy()
    np.testing.assert_allclose(r_c["corridor_lo_deg"].to_numpy()[sel], -r_i["corridor_hi_deg"].to_numpy()[sel])
    np.testing.assert_allclose(r_c["value_deg"].to_numpy()[sel], -r_i["value_deg"].to_numpy()[sel], atol=2e-6)


def test_the_dataframe_and_the_api_take_the_convention(runs):
    trial = exubio.read_trial(runs["c3d"])
    rec = exubio.reconstruct(trial, runs["model"], method="ls")
    df_i = exubio.to_dataframe(rec, model=runs["model"])
    df_c = exubio.to_dataframe(rec, model=runs["model"], signs="clinical")
    assert df_i.attrs["signs"] == "isb" and df_c.attrs["signs"] == "clinical"
    assert df_c.attrs["definitions"]["HT_X_elevation"].endswith("+ elevation")
    for n in ANATOMICAL_COLUMNS:
        np.testing.assert_allclose(df_c[f"{n}_deg"], _sign(n) * df_i[f"{n}_deg"])
        np.testing.assert_array_equal(df_c[f"{n}_u_deg"], df_i[f"{n}_u_deg"])
    peak = int(np.argmax(runs["truth_ht_deg"]))
    assert abs(df_c["HT_X_elevation_deg"].iloc[peak] - runs["truth_ht_deg"][peak]) < 2.0
    ang = exubio.angles(rec, runs["model"], signs="clinical")
    np.testing.assert_allclose(np.degrees(ang["HT_X_elevation"]), df_c["HT_X_elevation_deg"])
    # the API writes the files in the convention asked for, as the CLI does
    paths = exubio.write_results(rec, runs["root"] / "api", "abd", model=runs["model"], signs="clinical")
    assert Path(paths["csv"]).name == "abd.ls.csv"
    _, _, deg, _ = _csv(runs["root"] / "api")
    np.testing.assert_allclose(deg[:, ANATOMICAL_COLUMNS.index("HT_X_elevation")], df_c["HT_X_elevation_deg"], atol=2e-6)


def test_the_study_table_holds_the_files_values_and_their_convention(runs):
    from exubio.run.study_table import trial_rows

    for signs in ("isb", "clinical"):
        folder = runs["dirs"][signs]
        _, names, deg, _ = _csv(folder)
        rows = trial_rows(folder / "abd.ls.npz", subject="S", session="s1", trial="abd", task="abd", method="ls",
                          verdict="ok")
        assert set(rows["signs"]) == {signs}
        ht = rows["angle"] == "HT_X_elevation"
        np.testing.assert_allclose(rows["value_deg"][ht], deg[:, names.index("HT_X_elevation")], atol=1e-9)


def _protocol(tmp_path: Path, signs: str) -> Path:
    from exubio.protocol.load import resolve_protocol

    text = resolve_protocol("upper_limb_21").read_text(encoding="utf-8")
    path = tmp_path / f"p_{signs}.yaml"
    path.write_text(text.rstrip("\n") + f"\nsigns: {signs}\n", encoding="utf-8")
    return path


def test_the_protocol_key_sets_the_convention_and_the_cli_overrides_it(runs, tmp_path):
    proto = _protocol(tmp_path, "clinical")
    c3d = str(runs["c3d"])
    assert main(["-q", "reconstruct", c3d, "--method", "ls", "--protocol", str(proto), "--no-report",
                 "--out", str(tmp_path / "key")]) == 0
    assert main(["-q", "reconstruct", c3d, "--method", "ls", "--protocol", str(proto), "--signs", "isb", "--no-report",
                 "--out", str(tmp_path / "over")]) == 0
    _, _, by_key, _ = _csv(tmp_path / "key")
    _, _, over, _ = _csv(tmp_path / "over")
    _, _, cli, _ = _csv(runs["dirs"]["clinical"])
    _, _, isb, _ = _csv(runs["dirs"]["isb"])
    np.testing.assert_allclose(by_key, cli, atol=2e-6)
    np.testing.assert_allclose(over, isb, atol=2e-6)
    # a run with other signs into a folder with results does not keep them as if they were the same
    assert main(["-q", "reconstruct", c3d, "--method", "ls", "--protocol", str(proto), "--no-report",
                 "--out", str(tmp_path / "over")]) == 2


def test_a_bad_value_is_one_error_naming_the_key(tmp_path, capsys, runs):
    proto = _protocol(tmp_path, "upward")
    assert main(["-q", "reconstruct", str(runs["c3d"]), "--method", "ls", "--protocol", str(proto),
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "signs" in err and "upward" in err and str(proto.name) in err and "Traceback" not in err
    with pytest.raises(SystemExit) as exc:
        main(["reconstruct", str(runs["c3d"]), "--signs", "positive", "--out", str(tmp_path / "o2")])
    assert exc.value.code == 2 and "--signs" in capsys.readouterr().err
    (tmp_path / "t.c3d").write_bytes(b"")
    (tmp_path / "study.yaml").write_text("schema_version: 1\nsigns: raw\nsessions:\n  - subject: S\n    trials: [t.c3d]\n",
                                         encoding="utf-8")
    assert main(["-q", "study", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "st")]) == 2
    err = capsys.readouterr().err
    assert "study.yaml: signs" in err and "raw" in err and "Traceback" not in err
    with pytest.raises(exubio.InputError, match="signs"):
        exubio.to_dataframe(exubio.reconstruct(exubio.read_trial(runs["c3d"]), runs["model"], method="ls"),
                            model=runs["model"], signs="abduction")


def test_the_live_stream_publishes_in_the_protocols_convention(runs):
    """exubio live's output rows: the angles and their rates in the protocol's convention (the
    recording, ISB inside, is the same in both)."""
    import dataclasses
    import math

    from exubio.run.live.loop import LiveSession, SessionHooks
    from exubio.run.live.options import LiveOptions
    from exubio.run.live.outputs import ISB_NAMES
    from exubio.run.live.sources import Faults, ReplaySource

    trial = exubio.read_trial(runs["c3d"])
    protocol = exubio.load_protocol(model=runs["model"])
    rows = {}
    for signs in ("isb", "clinical"):
        got: list = []
        opts = dataclasses.replace(LiveOptions(), end_after_s=None, max_behind_s=math.inf, stall_s=math.inf)
        LiveSession(runs["model"], dataclasses.replace(protocol, signs=signs), ReplaySource(trial, speed=None, faults=Faults()),
                    options=opts, hooks=SessionHooks(publish=lambda row, ts, got=got: got.append(row))).run()
        rows[signs] = np.array(got)
    a = len(ISB_NAMES)
    expect = np.array([_sign(n) for n in ISB_NAMES])
    i, c = rows["isb"], rows["clinical"]
    assert i.shape == c.shape and i.shape[0] > 100
    np.testing.assert_allclose(c[:, :a], i[:, :a] * expect)  # the angles
    np.testing.assert_allclose(c[:, a:2 * a], i[:, a:2 * a] * expect)  # their rates flip with them
    # measured flags, residuals, verdict, tracking and the frame index (not frames_behind: how far the
    # loop lags depends on the machine's load, the last three channels are frames_behind, frame, timestamp)
    np.testing.assert_array_equal(c[:, 2 * a:-3], i[:, 2 * a:-3])
    np.testing.assert_array_equal(c[:, -2], i[:, -2])
    ht = ISB_NAMES.index("HT_X_elevation")
    assert np.nanmax(c[:, ht]) > 60.0 and np.nanmin(i[:, ht]) < -60.0  # the raised arm


def test_a_clinical_mot_plays_on_the_osim_exported_with_clinical_signs(runs, tmp_path):
    """The anatomical .osim exported with --signs clinical turns a reversed angle about the reversed
    axis: the clinical .mot's angles put its markers where exubio's model points were (and the ISB
    .osim's markers at the ISB .mot's angles, the same places)."""
    opensim = pytest.importorskip("opensim")
    from exubio.export import marker_table
    from exubio.io.results import read_npz

    model = runs["model"]
    rec = read_npz(runs["dirs"]["isb"] / "abd.ls.npz")
    name_of = {(seg, point): name for name, seg, point in marker_table(model)}
    kin_points = {}
    for signs in ("isb", "clinical"):
        assert main(["-q", "export-model", model.source, "--format", "osim", "--signs", signs,
                     "--out", str(tmp_path / f"{signs}.osim")]) == 0
        osim = opensim.Model(str(tmp_path / f"{signs}.osim"))
        state = osim.initSystem()
        coords = osim.getCoordinateSet()
        _, names, q = read_mot(runs["dirs"][signs] / "abd.ls.mot")
        markers = osim.getMarkerSet()
        got = []
        for i in range(0, rec.n_frames, 30):
            for k in range(coords.getSize()):
                c = coords.get(k)
                c.setValue(state, float(q[i, list(names).index(c.getName())]), False)
            osim.realizePosition(state)
            got.append([markers.get(n).getLocationInGround(state).to_numpy() for n in name_of.values()])
        kin_points[signs] = np.array(got)
    assert np.abs(kin_points["clinical"] - kin_points["isb"]).max() < 1e-5  # the same postures (CSV's 6 decimals)
    from exubio.model.kinematics import Kinematics

    kin = Kinematics(model)
    want = kin.points(rec.q_rad[::30], kin.point_set(list(name_of)))
    assert np.abs(kin_points["clinical"] - want).max() < 1e-5
