"""The joint moments' outputs (issue 36): the .sto of the generalized forces read back (a parser
written here and OpenSim's TimeSeriesTable); the same q, q', q'' through exubio, biorbd
(InverseDynamics on the exported .bioMod) and OpenSim's own inverse dynamics tool (on the exported
.osim, free thorax and all, and a .mot written by exubio's writer) give the same generalized
forces to 1e-6 N m, with the trunk still and moving (biorbd and OpenSim, free thorax); the .osim's
thorax coordinates place the thorax as exubio.export.thorax says; PF's inertia scale as a CLI
option and a protocol key, named in summary.json, the moments headers and the report; the study's
moments table matches the per-trial files; the benchmark script's figure."""
import dataclasses
import json
import locale

import numpy as np
import pytest
import yaml

from exubio.dynamics.inertia import dynamics_model
from exubio.dynamics.moments import joint_moments
from exubio.errors import InputError, ProtocolError
from exubio.export import write_biomod, write_osim
from exubio.export.sto import write_generalized_forces_sto
from exubio.export.thorax import (THORAX_COORDINATES, THORAX_TRANSLATIONS, thorax_coordinates, thorax_pose,
                                  with_thorax_inertia)
from exubio.io.results import write_mot
from exubio.model.load import load_model

TOL_NM = 1e-6
RATE_HZ, N_FRAMES = 20.0, 21


@pytest.fixture(autouse=True)
def _keep_the_locale():
    before = locale.setlocale(locale.LC_ALL)  # biorbd.Model() sets LC_ALL=C (see tests/test_export.py)
    yield
    locale.setlocale(locale.LC_ALL, before)


@pytest.fixture(scope="module")
def dyn():
    return dynamics_model(load_model(body_mass_kg=70.0), hand_load_kg=2.0)


def parse_sto(path):
    """(header key=value, column names, table (n, 1 + k)) of an OpenSim storage file."""
    lines = path.read_text(encoding="utf-8").splitlines()
    end = lines.index("endheader")
    header = dict(line.split("=", 1) for line in lines[1:end] if "=" in line)
    columns = lines[end + 1].split("\t")
    table = np.array([[float(x) for x in line.split("\t")] for line in lines[end + 2:] if line.strip()])
    return header, columns, table


def quadratic_motion(model, seed=0):
    """q(t) = A + B t + C t^2 per coordinate, in whole degrees, sampled at RATE_HZ: every sample is
    an exact decimal of a few places (a .mot's 6 decimals of degrees hold it exactly), and any
    spline of degree >= 2 through the samples (OpenSim's ID tool fits a quintic GCV spline) is the
    quadratic itself, so its q' and q'' are B + 2Ct and 2C exactly. Returns t, q, q', q'' (rad)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.degrees(np.clip(model.coordinate_ranges_rad.T, -np.pi, np.pi))  # a half turn each way where unbounded
    A = np.round((lo + hi) / 2)
    B = rng.integers(-20, 21, model.n_coordinates).astype(float)
    C = rng.integers(-30, 31, model.n_coordinates).astype(float)
    t = np.arange(N_FRAMES) / RATE_HZ
    T = t[:, None]
    q = np.radians(A + B * T + C * T ** 2)
    assert np.all((q >= model.coordinate_ranges_rad[:, 0]) & (q <= model.coordinate_ranges_rad[:, 1]))
    return t, q, np.radians(B + 2 * C * T), np.radians(np.broadcast_to(2 * C, q.shape))


def opensim_inverse_dynamics(opensim, osim_path, mot_path, out_dir, t_end):
    """OpenSim's InverseDynamicsTool on the files (no filter): its output as a TimeSeriesTable."""
    model = opensim.Model(str(osim_path))
    model.initSystem()
    tool = opensim.InverseDynamicsTool()
    tool.setModel(model)
    tool.setCoordinatesFileName(str(mot_path))
    tool.setStartTime(0.0)
    tool.setEndTime(t_end)
    tool.setLowpassCutoffFrequency(-1.0)
    tool.setResultsDir(str(out_dir))
    tool.setOutputGenForceFileName("id.sto")
    assert tool.run()
    return opensim.TimeSeriesTable(str(out_dir / "id.sto"))


# ------------------------------------------------------------------------------------------ .sto
def test_sto_round_trip(dyn, tmp_path):
    t, q, qd, qdd = quadratic_motion(dyn)
    m = joint_moments(dyn, q, qd, qdd, time_s=t, dynamic_model=dyn)
    m = dataclasses.replace(m, info={"method": "pf", "pf_inertia_scale": 0.1})
    path = write_generalized_forces_sto(tmp_path / "x.pf.moments.sto", m, notes={"note": "a=b\nc"})
    header, columns, table = parse_sto(path)
    names = list(dyn.coordinate_names)
    assert columns == ["time"] + [f"{n}_moment" for n in names]
    assert header["nRows"] == str(len(t)) and header["nColumns"] == str(len(names) + 1)
    assert header["inDegrees"] == "no" and header["pf_inertia_scale"] == "0.1" and header["note"] == "a:b c"
    assert "Dumas" in header["inertia_source"] and header["body_mass_kg"] == "70"
    np.testing.assert_allclose(table[:, 0], t, rtol=0, atol=1e-12)
    ref = np.column_stack([m.column(f"{n}_generalized_force_Nm") for n in names])
    np.testing.assert_allclose(table[:, 1:], ref, rtol=1e-11, atol=1e-12)
    opensim = pytest.importorskip("opensim")
    tab = opensim.TimeSeriesTable(str(path))
    assert list(tab.getColumnLabels()) == columns[1:]
    np.testing.assert_allclose(tab.getDependentColumn("gh_abduction_moment").to_numpy(),
                               m.column("gh_abduction_generalized_force_Nm"), rtol=1e-11, atol=1e-12)
    with pytest.raises(InputError, match="generalized-force"):
        write_generalized_forces_sto(tmp_path / "bad.sto", dataclasses.replace(m, columns=tuple(
            c.replace("generalized_force", "gf") for c in m.columns)))


# --------------------------------------------------------------- the three tools on the same motion
def test_exubio_biorbd_and_opensim_id_tool_agree(dyn, tmp_path):
    """exubio's generalized forces (its .sto), biorbd's InverseDynamics on the exported .bioMod and
    OpenSim's ID tool on the exported .osim (free thorax, its columns 0 in the .mot: the
    thorax-fixed model) and the .mot: equal to 1e-6 N m on every coordinate of the open chain."""
    opensim = pytest.importorskip("opensim")
    biorbd = pytest.importorskip("biorbd")
    t, q, qd, qdd = quadratic_motion(dyn)
    names = list(dyn.coordinate_names)
    m = joint_moments(dyn, q, qd, qdd, time_s=t, dynamic_model=dyn)
    _, columns, table = parse_sto(write_generalized_forces_sto(tmp_path / "exubio.sto", m))
    ours = table[:, 1:]
    assert np.abs(ours).max() > 10.0, "the motion loads the joints"
    bio = biorbd.Model(str(write_biomod(dyn, tmp_path / "dyn.bioMod")))
    ref = np.array([bio.InverseDynamics(a, b, c).to_array() for a, b, c in zip(q, qd, qdd)])
    np.testing.assert_allclose(ours, ref, rtol=0, atol=TOL_NM)
    mot = write_mot(tmp_path / "q.mot", t, [*THORAX_COORDINATES, *names], np.column_stack([np.zeros((len(t), 6)), q]),
                    metres=THORAX_TRANSLATIONS)
    osim = write_osim(dyn, tmp_path / "dyn.osim", coordinates="model")
    tab = opensim_inverse_dynamics(opensim, osim, mot, tmp_path, t[-1])
    assert list(tab.getColumnLabels())[6:] == columns[1:], "exubio's .sto names the columns as OpenSim's ID tool"
    np.testing.assert_allclose(np.asarray(tab.getIndependentColumn()), t, rtol=0, atol=1e-9)
    theirs = np.column_stack([tab.getDependentColumn(c).to_numpy() for c in columns[1:]])
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=TOL_NM)
    # the thorax's residual force: the whole body's weight and the arm's acceleration, through the ground
    mass = with_thorax_inertia(dyn).segments[0].mass_kg + sum(s.mass_kg for s in dyn.segments[1:])
    assert mass == pytest.approx(70 * 0.331 + sum(s.mass_kg for s in dyn.segments[1:]), rel=1e-3)
    fy = tab.getDependentColumn("thorax_ty_force").to_numpy()
    assert np.abs(fy / (mass * 9.80665) - 1).max() < 0.05  # the arm's accelerations move it a little


def test_a_moving_trunk_through_biorbd_and_opensim_id_tool(dyn, tmp_path):
    """The thorax's six coordinates moving too (quadratic: tilt, list, rotation and translations):
    OpenSim's ID tool on the .osim and .mot and biorbd on the free-thorax .bioMod agree on all 19
    generalized forces to 1e-6 N m; the arm's differ from the thorax-fixed ones (the trunk's
    motion matters)."""
    opensim = pytest.importorskip("opensim")
    biorbd = pytest.importorskip("biorbd")
    t, q, qd, qdd = quadratic_motion(dyn, seed=3)
    T = t[:, None]
    rot = np.array([[5.0, 10.0, -40.0], [-3.0, -20.0, 25.0], [10.0, 30.0, 20.0]]).T  # A, B, C (deg) per angle
    lin = np.array([[0.1, 0.2, 0.5], [1.2, 0.1, -1.0], [-0.05, -0.3, 0.25]]).T  # A, B, C (m) per translation
    qa, qx = rot[0] + rot[1] * T + rot[2] * T ** 2, lin[0] + lin[1] * T + lin[2] * T ** 2
    names = [*THORAX_COORDINATES, *dyn.coordinate_names]
    mot = write_mot(tmp_path / "q.mot", t, names, np.column_stack([np.radians(qa), qx, q]), metres=THORAX_TRANSLATIONS)
    tab = opensim_inverse_dynamics(opensim, write_osim(dyn, tmp_path / "dyn.osim", coordinates="model"), mot,
                                   tmp_path, t[-1])
    theirs = np.column_stack([tab.getDependentColumn(n + ("_force" if n in THORAX_TRANSLATIONS else "_moment")).to_numpy()
                              for n in names])
    bio = biorbd.Model(str(write_biomod(dyn, tmp_path / "free.bioMod", thorax="free")))
    assert bio.nbQ() == 19
    bq = np.column_stack([qx, np.radians(qa), q])  # biorbd: translations, then tilt, list, rotation, then exubio's
    bqd = np.column_stack([lin[1] + 2 * lin[2] * T, np.radians(rot[1] + 2 * rot[2] * T), qd])
    bqdd = np.column_stack([np.broadcast_to(2 * lin[2], qx.shape), np.broadcast_to(np.radians(2 * rot[2]), qa.shape), qdd])
    ref = np.array([bio.InverseDynamics(a, b, c).to_array() for a, b, c in zip(bq, bqd, bqdd)])
    ref = np.column_stack([ref[:, 3:6], ref[:, 0:3], ref[:, 6:]])
    np.testing.assert_allclose(theirs, ref, rtol=0, atol=TOL_NM)
    fixed = joint_moments(dyn, q, qd, qdd, dynamic_model=dyn)
    arm = np.column_stack([fixed.column(f"{n}_generalized_force_Nm") for n in dyn.coordinate_names])
    assert np.abs(theirs[:, 6:] - arm).max() > 1.0, "the trunk's motion changes the arm's moments"


def test_thorax_coordinates_place_the_thorax(dyn, tmp_path):
    """thorax_coordinates of a pose, set on the .osim's free joint, put the thorax body at that pose
    in OpenSim's ground; thorax_pose inverts them."""
    rng = np.random.default_rng(4)
    R, origin = thorax_pose(np.column_stack([rng.uniform(-1.2, 1.2, (6, 3)), rng.normal(0, 0.5, (6, 3))]))
    c = thorax_coordinates(R, origin)
    R2, o2 = thorax_pose(c)
    np.testing.assert_allclose(R2, R, atol=1e-12)
    np.testing.assert_allclose(o2, origin, atol=1e-12)
    opensim = pytest.importorskip("opensim")
    model = opensim.Model(str(write_osim(dyn, tmp_path / "dyn.osim", coordinates="model")))
    state = model.initSystem()
    coords = model.getCoordinateSet()
    body = model.getBodySet().get("thorax")
    assert body.getMass() == pytest.approx(0.028 * 20.866630055554726 / 1.7650184258291826 * 70.0, rel=1e-12)
    for k in range(len(c)):
        for j, name in enumerate(THORAX_COORDINATES):
            coords.get(name).setValue(state, float(c[k, j]), False)
        model.realizePosition(state)
        X = body.getTransformInGround(state)
        got_R = np.array([[X.R().get(i, j) for j in range(3)] for i in range(3)])
        np.testing.assert_allclose(got_R, R[k], atol=1e-12)
        np.testing.assert_allclose(X.p().to_numpy(), origin[k], atol=1e-12)
    weld = (tmp_path / "weld.osim")
    write_osim(dyn, weld, coordinates="model", thorax="weld")
    assert "WeldJoint" in weld.read_text(encoding="utf-8") and "thorax_tilt" not in weld.read_text(encoding="utf-8")


# ------------------------------------------------------------------------ PF's inertia scale option
def test_pf_inertia_scale_option_and_protocol_key(tmp_path):
    import argparse

    from exubio.cli import build_parser
    from exubio import load_protocol
    from exubio.run.moments_outputs import pf_inertia_entry, pf_options

    protocol = tmp_path / "p.yaml"
    protocol.write_text(yaml.safe_dump({"schema_version": 1, "extends": "upper_limb_21",
                                        "defaults": {"pf_inertia_scale": 0.3}}), encoding="utf-8")
    prot = load_protocol(protocol)
    assert prot.pf_inertia_scale == 0.3
    args = build_parser().parse_args(["reconstruct", "t.c3d", "--out", "o"])
    assert pf_options(args, prot) == {"gravity": False, "inertia_scale": 0.3}
    assert pf_options(args, load_protocol()) == {"gravity": False}  # PF's own default (0.1) stays
    args = build_parser().parse_args(["reconstruct", "t.c3d", "--out", "o", "--pf-inertia-scale", "1"])
    assert pf_options(args, prot)["inertia_scale"] == 1.0  # the command line wins
    with pytest.raises(InputError, match="--pf-inertia-scale"):
        pf_options(argparse.Namespace(pf_inertia_scale=-1.0), prot)
    protocol.write_text(yaml.safe_dump({"schema_version": 1, "extends": "upper_limb_21",
                                        "defaults": {"pf_inertia_scale": 0}}), encoding="utf-8")
    with pytest.raises(ProtocolError, match="defaults.pf_inertia_scale"):
        load_protocol(protocol)
    # a fallback run: the scale used and the one asked, and why they differ
    info = {"options": {"inertia_scale": 0.01}, "fallback": {"first_run": "Newton failed", "asked_inertia_scale": 0.1,
                                                              "options": {"inertia_scale": 0.01}}}
    entry = pf_inertia_entry(info)
    assert entry["used"] == 0.01 and entry["asked"] == 0.1 and "Newton failed" in entry["fallback"]
    assert pf_inertia_entry({"options": {"step_s": 0.01}}) is None  # LS: none
    # ... and the report says it: page 1's figures line, the moments page's title
    from exubio.report.moments_page import moments_page
    from exubio.report.trial_report import _pf_inertia

    assert _pf_inertia(entry) == "; PF's segment inertia x0.01, fallback run (asked x0.1)" and _pf_inertia(None) == ""
    page = moments_page(np.arange(3.0), ("GH_X_moment_Nm",), np.zeros((3, 1)), title="t", method="pf",
                        moments_summary={"body_mass_kg": 70.0, "hand_load_kg": 0.0}, pf_inertia=entry)
    assert "PF inertia scale x0.01" in page._suptitle.get_text() and "asked x0.1" in page._suptitle.get_text()


# ------------------------------------------------------------------------- a run's files and a study
@pytest.fixture(scope="module")
def trial_file(tmp_path_factory):
    from exubio.cli import main

    c3d = tmp_path_factory.mktemp("trial") / "raise.c3d"
    assert main(["simulate", "--motion", "abduction", "--duration", "4", "--rate", "50", "--out", str(c3d)]) == 0
    return c3d


@pytest.mark.exudyn
def test_reconstruct_writes_the_sto_and_names_pf_inertia_scale(trial_file, tmp_path):
    from exubio.cli import main
    from exubio.dynamics.moments_file import read_moments_csv
    from exubio.report.moments_page import trial_moments_figure
    from exubio.report.trial_report import read_angles

    out = tmp_path / "out"
    assert main(["reconstruct", str(trial_file), "--method", "both", "--body-mass", "70", "--hand-load-kg", "1",
                 "--pf-inertia-scale", "0.5", "--out", str(out), "-q"]) == 0
    for method in ("pf", "ls"):
        header, columns, table = parse_sto(out / f"raise.{method}.moments.sto")
        t, cols, values = read_moments_csv(out / f"raise.{method}.moments.csv")
        names = [c.removesuffix("_moment") for c in columns[1:]]
        assert names == list(load_model().coordinate_names)
        np.testing.assert_allclose(table[:, 0], t, rtol=0, atol=1e-9)
        ref = np.column_stack([values[:, cols.index(f"{n}_generalized_force_Nm")] for n in names])
        np.testing.assert_allclose(table[:, 1:], ref, rtol=1e-8, atol=1e-9)  # the CSV prints 9 digits
        summary = json.loads((out / f"raise.{method}.summary.json").read_text(encoding="utf-8"))
        contact = summary["moments"]["scapulothoracic_contact"]
        for point in ("TS", "AI"):
            v = values[:, cols.index(f"{point}_contact_normal_N")]
            assert contact[point]["median_N"] == pytest.approx(np.median(v), abs=1e-4)
            assert contact[point]["peak_N"] == pytest.approx(v[np.argmax(np.abs(v))], abs=1e-4)
            assert contact[point]["compression_share"] == pytest.approx(np.mean(v > 0), abs=1e-4)
        assert summary["moments"]["files"] == [f"raise.{method}.moments.csv", f"raise.{method}.moments.sto"]
        csv_text = (out / f"raise.{method}.moments.csv").read_text(encoding="utf-8")
        page = trial_moments_figure(out / f"raise.{method}.npz", "raise", method, read_angles(out / f"raise.{method}.npz"),
                                    summary)
        page_text = " ".join(t.get_text() for t in page.findobj(match=lambda a: hasattr(a, "get_text")))
        mot = (out / f"raise.{method}.mot").read_text(encoding="utf-8").splitlines()
        mot_columns = mot[mot.index("endheader") + 1].split("\t")
        assert mot_columns[-6:] == list(THORAX_COORDINATES)
        # the simulator's still thorax, measured from its markers: yawed LAB_YAW_DEG about the lab's vertical
        # (Z up), its origin at LAB_ORIGIN_M; the .mot's ground has Y up (lab X, Z, -Y)
        from exubio.synth.simulate import LAB_ORIGIN_M, LAB_YAW_DEG

        x, y, z = LAB_ORIGIN_M
        expected = [0.0, 0.0, LAB_YAW_DEG, x, z, -y]
        thorax_rows = np.array([[float(v) for v in line.split("\t")[-6:]] for line in mot[mot.index("endheader") + 2:]])
        np.testing.assert_allclose(thorax_rows, np.tile(expected, (len(thorax_rows), 1)), atol=1e-5)
        if method == "pf":  # PF ran with the option, and every output says so
            assert summary["info"]["options"]["inertia_scale"] == 0.5
            assert summary["pf_inertia_scale"]["used"] == 0.5 and summary["pf_inertia_scale"]["asked"] == 0.5
            assert header["pf_inertia_scale"] == "0.5" and "pf_inertia_scale 0.5" in csv_text
            assert "PF inertia scale x0.5" in page_text
        else:
            assert "pf_inertia_scale" not in summary and "pf_inertia_scale" not in header
            assert "inertia scale" not in page_text and "LS reconstruction" in csv_text
    assert (out / "raise.report.pdf").is_file()
    assert main(["reconstruct", str(trial_file), "--method", "pf", "--pf-inertia-scale", "0", "--out",
                 str(tmp_path / "bad"), "-q", "--no-report"]) == 2
    assert main(["reconstruct", str(trial_file), "--method", "ls", "--pf-inertia-scale", "1", "--out",
                 str(tmp_path / "bad"), "-q", "--no-report"]) == 2  # no PF run: the option would change nothing


@pytest.mark.exudyn
def test_study_moments_table(trial_file, tmp_path):
    import shutil

    import exubio
    from exubio.cli import main
    from exubio.dynamics.moments_file import read_moments_csv
    from exubio.run.study import load_study

    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        shutil.copy(trial_file, tmp_path / sub / "raise.c3d")
    study = tmp_path / "study.yaml"
    sessions = [{"subject": "A", "trials": ["a/*.c3d"], "static_frames": "0:20", "body_mass_kg": 70, "hand_load_kg": 1},
                {"subject": "B", "trials": ["b/*.c3d"], "static_frames": "0:20"}]
    study.write_text(yaml.safe_dump({"schema_version": 1, "methods": ["ls"], "report": False, "sessions": sessions}),
                     encoding="utf-8")
    out = tmp_path / "out"
    assert main(["study", str(study), "--out", str(out), "-q"]) == 0
    df = exubio.load_study(out, table="moments")
    assert set(df["subject"]) == {"A"}, "only the session with a body mass has moments"
    t, cols, values = read_moments_csv(out / "A" / "s1" / "raise" / "raise.ls.moments.csv")
    assert len(df) == values.size and set(df["method"]) == {"ls"}
    gh = df[df["quantity"] == "GH_X_moment_Nm"]
    np.testing.assert_allclose(gh["value"].to_numpy(), values[:, cols.index("GH_X_moment_Nm")], rtol=0, atol=0)
    np.testing.assert_allclose(gh["time_s"].to_numpy(), t, rtol=0, atol=0)
    assert set(gh["unit"]) == {"N m"} and set(df[df["quantity"] == "TS_contact_normal_N"]["unit"]) == {"N"}
    assert (df["body_mass_kg"] == 70).all() and (df["hand_load_kg"] == 1).all()
    assert not list((out / "B").rglob("*.moments.csv"))
    # run again with --body-mass: B's complete trial had no moments, so it runs again (A's is kept)
    done_a = (out / "A" / "s1" / "raise" / "DONE.json").stat().st_mtime_ns
    assert main(["study", str(study), "--out", str(out), "-q", "--body-mass", "80"]) == 0
    df = exubio.load_study(out, table="moments")
    assert set(df["subject"]) == {"A", "B"} and set(df[df["subject"] == "B"]["body_mass_kg"]) == {80.0}
    assert (out / "A" / "s1" / "raise" / "DONE.json").stat().st_mtime_ns == done_a
    # --body-mass: every session without its own
    spec = load_study(study, body_mass_kg=80.0)
    assert [(s.body_mass_kg, s.hand_load_kg) for s in spec.sessions] == [(70.0, 1.0), (80.0, 0.0)]
    sessions[1]["hand_load_kg"] = 2
    study.write_text(yaml.safe_dump({"schema_version": 1, "sessions": sessions}), encoding="utf-8")
    with pytest.raises(InputError, match=r"sessions\[1\]\.hand_load_kg"):
        load_study(study)
    with pytest.raises(InputError, match="moments.parquet"):
        exubio.load_study(tmp_path, table="moments")


@pytest.mark.exudyn
def test_opensim_id_tool_on_exubios_own_mot_gives_its_moments(trial_file, tmp_path):
    """The user's path: `exubio reconstruct --body-mass` writes the .mot (anatomical angles and the
    thorax's six columns), `exubio export-model --body-mass` the .osim with the same inertia; OpenSim's
    ID tool on them gives exubio's elbow, forearm and wrist moments (the coordinates the two share)
    within 0.5 % of their peak (OpenSim differentiates the .mot's 6-decimal angles by its own
    splines, exubio uses LS's q', q'')."""
    opensim = pytest.importorskip("opensim")
    from exubio.cli import main
    from exubio.dynamics.moments_file import read_moments_csv

    out = tmp_path / "out"
    assert main(["reconstruct", str(trial_file), "--method", "ls", "--body-mass", "70", "--hand-load-kg", "2",
                 "--out", str(out), "-q", "--no-report"]) == 0
    osim = tmp_path / "subject.osim"
    assert main(["export-model", str(load_model().source), "--format", "osim", "--out", str(osim), "--body-mass", "70",
                 "--hand-load-kg", "2"]) == 0
    t, cols, values = read_moments_csv(out / "raise.ls.moments.csv")
    tab = opensim_inverse_dynamics(opensim, osim, out / "raise.ls.mot", tmp_path, t[-1])
    np.testing.assert_allclose(np.asarray(tab.getIndependentColumn()), t, atol=1e-6)
    for name in ("elbow_flexion", "forearm_pronation", "wrist_flexion", "wrist_radial_deviation"):
        ours = values[:, cols.index(f"{name}_moment_Nm")]
        theirs = tab.getDependentColumn(f"{name}_moment").to_numpy()
        assert np.abs(theirs - ours).max() < 0.005 * np.abs(ours).max(), name
    assert main(["export-model", str(load_model().source), "--format", "osim", "--out", str(tmp_path / "x.osim"),
                 "--hand-load-kg", "2"]) == 2


@pytest.mark.exudyn
def test_opensim_id_tool_on_the_mot_of_a_leaning_trunk_gives_exubios_moments(tmp_path):
    """The trunk leans 20 deg during the raise: the .mot's six thorax columns carry the thorax's pose
    measured from its markers, and OpenSim's ID tool on that .mot and the free-thorax .osim gives
    exubio's elbow, forearm and wrist moments (which the trunk's motion and the direction of gravity
    change) within 1 % of their peak; with the thorax columns zeroed it does not."""
    opensim = pytest.importorskip("opensim")
    from exubio.cli import main
    from exubio.dynamics.moments_file import read_moments_csv

    c3d = tmp_path / "lean.c3d"
    assert main(["simulate", "--motion", "abduction", "--duration", "4", "--rate", "50", "--thorax-lean-deg", "20",
                 "--out", str(c3d)]) == 0
    out = tmp_path / "out"
    assert main(["reconstruct", str(c3d), "--method", "ls", "--body-mass", "70", "--hand-load-kg", "2",
                 "--out", str(out), "-q", "--no-report"]) == 0
    assert "exubio_thorax_columns=measured" in (out / "lean.ls.mot").read_text(encoding="utf-8")
    osim = tmp_path / "subject.osim"
    assert main(["export-model", str(load_model().source), "--format", "osim", "--out", str(osim), "--body-mass", "70",
                 "--hand-load-kg", "2"]) == 0
    t, cols, values = read_moments_csv(out / "lean.ls.moments.csv")
    tab = opensim_inverse_dynamics(opensim, osim, out / "lean.ls.mot", tmp_path, t[-1])
    worst = {}
    for name in ("elbow_flexion", "forearm_pronation", "wrist_flexion", "wrist_radial_deviation"):
        ours = values[:, cols.index(f"{name}_moment_Nm")]
        theirs = tab.getDependentColumn(f"{name}_moment").to_numpy()
        worst[name] = float(np.abs(theirs - ours).max() / np.abs(ours).max())
    assert max(worst.values()) < 0.01, worst
    text = (out / "lean.ls.mot").read_text(encoding="utf-8").split("endheader\n")
    head, rows = text[0], [r.split("\t") for r in text[1].strip().splitlines()]
    thorax = [i for i, c in enumerate(rows[0]) if c.startswith("thorax_")]
    zeroed = "\n".join("\t".join("0" if i in thorax and k else v for i, v in enumerate(r)) for k, r in enumerate(rows))
    (tmp_path / "still.mot").write_text(head + "endheader\n" + zeroed + "\n", encoding="utf-8")
    still = opensim_inverse_dynamics(opensim, osim, tmp_path / "still.mot", tmp_path / "still", t[-1])
    ours = values[:, cols.index("elbow_flexion_moment_Nm")]
    assert np.abs(still.getDependentColumn("elbow_flexion_moment").to_numpy() - ours).max() > 0.05 * np.abs(ours).max()
