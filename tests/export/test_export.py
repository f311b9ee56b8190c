"""Model export: the .osim and .bioMod files exubio writes, loaded by the opensim and biorbd
packages, put every model point where exubio's kinematics puts it (<= 1e-6 m) for random
postures, keep names, ranges, masses and inertias exactly, and replay a reconstruction; for the
generic model and a model calibrated the way `exubio calibrate` does."""
import dataclasses
import locale

import numpy as np
import pytest

from exubio.calibration import marker_point_names
from exubio.errors import InputError, ModelError
from exubio.export import marker_table, write_biomod, write_osim
from exubio.export.thorax import THORAX_COORDINATES, THORAX_TRANSLATIONS, with_thorax_inertia
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model
from exubio.io.results import read_npz
from exubio.run.pipeline import reconstruct_file
from exubio.run.inputs import load_session, protocol_for_model
from exubio.run.session import StaticSpec, calibrate_file
from exubio.io.resources import shipped_file

@pytest.fixture(autouse=True)
def _keep_the_locale():
    """biorbd.Model() sets the C locale of the whole process (LC_ALL=C: Python's default text
    encoding becomes ASCII); put the user's back after each test so later tests are unaffected."""
    before = locale.setlocale(locale.LC_ALL)
    yield
    locale.setlocale(locale.LC_ALL, before)


EXAMPLE = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
MODEL_PATH = shipped_file("exubio.models", "upper_extremity.yaml", "models")
TOL_M = 1e-6
N_POSTURES = 20


@pytest.fixture(scope="module")
def model_files(tmp_path_factory):
    """The generic model file and one calibrated as `exubio calibrate` does (first 0.2 s of the
    shipped example, written by save_model)."""
    subject = tmp_path_factory.mktemp("calibrated") / "subject.yaml"
    calibrate_file(EXAMPLE, spec=StaticSpec(frames="0:20"), out_path=subject)
    return {"generic": None, "calibrated": subject}


@pytest.fixture(scope="module", params=["generic", "calibrated"])
def exported(request, model_files):
    path = model_files[request.param]
    model = load_model() if path is None else load_model(path)
    if request.param == "calibrated":
        assert model.metadata["calibration"], "the calibrated model file records its calibration"
    return model


def as_written(ranges_rad):
    """The ranges as the files hold them: an unbounded side as one turn
    (test_an_unlimited_range_is_written_as_one_turn)."""
    return np.where(np.isfinite(ranges_rad), ranges_rad, np.sign(ranges_rad) * 2 * np.pi)


def postures(model, n=N_POSTURES, seed=0):
    """q = 0, both range limits of every coordinate (a half turn each way where unbounded), and n random
    postures inside the ranges."""
    lo, hi = np.clip(model.coordinate_ranges_rad.T, -np.pi, np.pi)
    rng = np.random.default_rng(seed)
    return np.vstack([np.zeros(len(lo)), lo, hi, rng.uniform(lo, hi, size=(n, len(lo)))])


def exubio_markers(model, q):
    kin = Kinematics(model)
    points = kin.point_set([(seg, point) for _, seg, point in marker_table(model)])
    return kin.points(q, points)


# -------------------------------------------------------------------------------------- OpenSim
def load_osim(opensim, path):
    osim_model = opensim.Model(str(path))
    return osim_model, osim_model.initSystem()


def osim_markers(osim_model, state, model, q):
    coords = osim_model.getCoordinateSet()
    for name, value in zip(model.coordinate_names, q):
        coords.get(name).setValue(state, float(value))
    osim_model.realizePosition(state)
    markers = osim_model.getMarkerSet()
    return np.array([markers.get(name).getLocationInGround(state).to_numpy() for name, _, _ in marker_table(model)])


def test_osim_markers_match_exubio_kinematics(exported, tmp_path):
    opensim = pytest.importorskip("opensim")
    osim_model, state = load_osim(opensim, write_osim(exported, tmp_path / "model.osim", coordinates="model"))
    qs = postures(exported)
    expected = exubio_markers(exported, qs)
    for q, ref in zip(qs, expected):
        err = np.linalg.norm(osim_markers(osim_model, state, exported, q) - ref, axis=1)
        assert err.max() <= TOL_M, f"max marker error {err.max():.2e} m at q = {q}"


def test_osim_names_ranges_and_inertia_round_trip(exported, tmp_path):
    opensim = pytest.importorskip("opensim")
    osim_model, _ = load_osim(opensim, write_osim(exported, tmp_path / "model.osim", coordinates="model"))
    coords = osim_model.getCoordinateSet()
    assert [coords.get(i).getName() for i in range(coords.getSize())] == [*THORAX_COORDINATES, *exported.coordinate_names]
    for name in THORAX_COORDINATES:  # the thorax's free joint (exubio.export.thorax)
        linear = name in THORAX_TRANSLATIONS
        assert coords.get(name).getMotionType() == (opensim.Coordinate.Translational if linear
                                                    else opensim.Coordinate.Rotational)
    exported = with_thorax_inertia(exported)  # the .osim carries the thorax's mass
    for name, (lo, hi) in zip(exported.coordinate_names, as_written(exported.coordinate_ranges_rad)):
        c = coords.get(name)
        assert (c.getRangeMin(), c.getRangeMax()) == (lo, hi)
        assert c.getDefaultValue() == 0.0 and not c.getDefaultClamped()
        assert c.getMotionType() == opensim.Coordinate.Rotational
    joints = osim_model.getJointSet()
    assert {joints.get(i).getName() for i in range(joints.getSize())} >= {
        s.joint.name for s in exported.segments if s.joint is not None}
    markers = osim_model.getMarkerSet()
    table = marker_table(exported)
    assert markers.getSize() == len(table) == sum(len(s.points) for s in exported.segments)
    for name, seg, point in table:
        marker = markers.get(name)
        assert marker.getParentFrame().getName() == seg
        assert np.array_equal(marker.get_location().to_numpy(), exported.segment(seg).points[point])
    bodies = osim_model.getBodySet()
    assert bodies.getSize() == len(exported.segments)
    for seg in exported.segments:
        body = bodies.get(seg.name)
        inertia = body.getInertia()
        tensor = np.asarray(seg.inertia_kgm2)
        assert body.getMass() == seg.mass_kg
        assert np.array_equal(body.getMassCenter().to_numpy(), seg.com_m)
        assert np.array_equal(inertia.getMoments().to_numpy(), np.diag(tensor))
        assert np.array_equal(inertia.getProducts().to_numpy(), tensor[[0, 0, 1], [1, 2, 2]])
    assert osim_model.getTotalMass(osim_model.initSystem()) == pytest.approx(
        sum(s.mass_kg for s in exported.segments), rel=1e-15)


def test_osim_states_what_it_cannot_express(exported, tmp_path):
    text = write_osim(exported, tmp_path / "model.osim", coordinates="model").read_text(encoding="utf-8")
    head = text[: text.index("<OpenSimDocument")]
    assert "NOT EXPRESSED" in head and "open chain" in head and "ellipsoid" in head
    for seg, point in exported.ellipsoid.contact_points:
        assert f"{point} on {seg}" in head


# -------------------------------------------------------------------------------------- biorbd
def test_biomod_markers_match_exubio_kinematics(exported, tmp_path):
    biorbd = pytest.importorskip("biorbd")
    bio = biorbd.Model(str(write_biomod(exported, tmp_path / "model.bioMod")))
    assert bio.nbQ() == exported.n_coordinates
    assert [n.to_string() for n in bio.markerNames()] == [name for name, _, _ in marker_table(exported)]
    qs = postures(exported)
    expected = exubio_markers(exported, qs)
    for q, ref in zip(qs, expected):
        got = np.array([m.to_array() for m in bio.markers(q)])
        err = np.linalg.norm(got - ref, axis=1)
        assert err.max() <= TOL_M, f"max marker error {err.max():.2e} m at q = {q}"


def test_biomod_ranges_and_inertia_round_trip(exported, tmp_path):
    biorbd = pytest.importorskip("biorbd")
    path = write_biomod(exported, tmp_path / "model.bioMod")
    bio = biorbd.Model(str(path))
    segments = {bio.segment(i).name().to_string(): bio.segment(i) for i in range(bio.nbSegment())}
    ranges = [(r.min(), r.max()) for s in segments.values() for r in s.QRanges()]
    assert ranges == [tuple(r) for r in as_written(exported.coordinate_ranges_rad)]
    text = path.read_text(encoding="utf-8")
    for seg in exported.segments:
        c = segments[seg.name].characteristics()
        tensor = np.asarray(seg.inertia_kgm2)
        assert c.mass() == seg.mass_kg
        assert np.array_equal(c.CoM().to_array(), seg.com_m)
        # biorbd (RBDL) keeps the inertia about the segment origin and gives back I_com to round-off
        np.testing.assert_allclose(c.inertia().to_array(), tensor, rtol=0, atol=1e-15 * np.abs(tensor).max())
        # the file itself holds exubio's numbers exactly
        block = text.split(f"\nsegment {seg.name}\n")[1].split("endsegment")[0].split()
        at = block.index("inertia")
        assert np.array_equal(np.array(block[at + 1:at + 10], dtype=float).reshape(3, 3), tensor)
    assert bio.mass() == pytest.approx(sum(s.mass_kg for s in exported.segments), rel=1e-15)
    head = text.split("version 4")[0]
    assert "NOT EXPRESSED" in head and "open chain" in head
    assert all(name in head for name in exported.coordinate_names)


def test_osim_and_biomod_have_the_same_mass_matrix(exported, tmp_path):
    """Dynamics cross-check: both files give the same joint-space mass matrix (same masses,
    centres of mass and inertias in the same frames)."""
    opensim = pytest.importorskip("opensim")
    biorbd = pytest.importorskip("biorbd")
    osim_model, state = load_osim(opensim, write_osim(exported, tmp_path / "model.osim", coordinates="model",
                                                      thorax="weld"))
    bio = biorbd.Model(str(write_biomod(exported, tmp_path / "model.bioMod")))
    for q in postures(exported, n=3)[3:]:
        osim_markers(osim_model, state, exported, q)  # sets q
        mass = opensim.Matrix()
        osim_model.getMatterSubsystem().calcM(state, mass)
        m_osim = np.array([[mass.get(i, j) for j in range(mass.ncol())] for i in range(mass.nrow())])
        np.testing.assert_allclose(m_osim, bio.massMatrix(q).to_array(), rtol=0, atol=1e-12)


# -------------------------------------------------------------------------------------- replay
@pytest.fixture(scope="module")
def reconstruction(tmp_path_factory, model_files):
    """`exubio reconstruct` (LS) of the shipped example with each model: its .mot and q."""
    out = {}
    for key, path in model_files.items():
        session = load_session(model_path=path)
        model = session.model
        folder = tmp_path_factory.mktemp(f"recon_{key}")
        [outcome] = reconstruct_file(EXAMPLE, folder, methods=["ls"], session=session)
        paths = outcome.paths
        out[model.name] = read_npz(paths["npz"]), paths["mot"]  # with the model points (streamed to the file)
    return out


def test_reconstruct_mot_plays_on_exported_osim(exported, reconstruction, tmp_path):
    """exubio's .mot carries the anatomical angles; the anatomical .osim (SC, AC, GH between the ISB
    frames, the angles as its coordinates) replays it: its markers at the .mot's angles are the
    model points exubio tracked."""
    from exubio.model.angles import anatomical_table

    opensim = pytest.importorskip("opensim")
    rec, mot = reconstruction[exported.name]
    osim_model, state = load_osim(opensim, write_osim(exported, tmp_path / "model.osim"))
    coords = osim_model.getCoordinateSet()
    table = opensim.TimeSeriesTable(str(mot))
    labels = list(table.getColumnLabels())
    assert table.getTableMetaDataAsString("inDegrees") == "yes"
    names, angles = anatomical_table(exported, rec.q_rad)
    assert labels == [*names, *THORAX_COORDINATES]  # the thorax's free joint: 0, the thorax-fixed model
    coordinates = [coords.get(i).getName() for i in range(coords.getSize())]
    assert set(coordinates) <= set(labels), "every coordinate of the .osim is a column of the .mot"
    np.testing.assert_allclose(np.asarray(table.getIndependentColumn()), rec.time_s, rtol=0, atol=5e-7)
    for name in THORAX_COORDINATES:
        assert not table.getDependentColumn(name).to_numpy().any()
    for j, name in enumerate(names):  # degrees, printed to 1e-6 deg
        values = table.getDependentColumn(name).to_numpy()
        np.testing.assert_allclose(values, np.degrees(angles[:, j]), rtol=0, atol=5.01e-7, err_msg=name)

    # OpenSim's own unit handling (Storage, degrees -> radians by each coordinate's motion type)
    storage = opensim.Storage(str(mot))
    osim_model.getSimbodyEngine().convertDegreesToRadians(storage)
    q_mot = {}
    for name in (c for c in coordinates if c not in THORAX_COORDINATES):
        column = opensim.ArrayDouble()
        storage.getDataColumn(name, column)
        q_mot[name] = np.array([column.get(i) for i in range(column.getSize())])
        np.testing.assert_allclose(q_mot[name], angles[:, names.index(name)], rtol=0, atol=1e-8)

    # replay: the .osim's markers at the .mot's angles are the model points exubio tracked
    protocol = protocol_for_model(exported)
    point_of = marker_point_names(protocol, exported)
    name_of = {(seg, point): name for name, seg, point in marker_table(exported)}
    wanted = [name_of[(m.segment, point_of[m.name])] for m in protocol.markers]
    markers = osim_model.getMarkerSet()
    for i in range(0, rec.n_frames, 50):
        for name in q_mot:
            coords.get(name).setValue(state, float(q_mot[name][i]), False)
        osim_model.realizePosition(state)
        got = np.array([[markers.get(n).getLocationInGround(state).get(k) for k in range(3)] for n in wanted])
        assert np.abs(got - rec.model_points_m[i]).max() <= TOL_M


def test_reconstruction_replays_on_exported_biomod(exported, reconstruction, tmp_path):
    biorbd = pytest.importorskip("biorbd")
    rec, _ = reconstruction[exported.name]
    bio = biorbd.Model(str(write_biomod(exported, tmp_path / "model.bioMod")))
    protocol = protocol_for_model(exported)
    point_of = marker_point_names(protocol, exported)
    all_points = [(seg, point) for _, seg, point in marker_table(exported)]
    columns = [all_points.index((m.segment, point_of[m.name])) for m in protocol.markers]
    for i in range(0, rec.n_frames, 10):
        got = np.array([m.to_array() for m in bio.markers(rec.q_rad[i])])[columns]
        assert np.abs(got - rec.model_points_m[i]).max() <= TOL_M


# -------------------------------------------------------------------------------------- files
@pytest.mark.parametrize("writer, suffix", [(write_osim, ".osim"), (write_biomod, ".bioMod")])
def test_existing_file_is_not_replaced_without_overwrite(writer, suffix, tmp_path):
    model = load_model()
    path = tmp_path / f"model{suffix}"
    path.write_text("keep me", encoding="utf-8")
    with pytest.raises(InputError, match=str(path)):
        writer(model, path)
    assert path.read_text(encoding="utf-8") == "keep me"
    assert writer(model, path, overwrite=True) == path
    assert path.read_text(encoding="utf-8") != "keep me"
    assert [p.name for p in tmp_path.iterdir()] == [path.name], "no temporary file left behind"


def test_missing_folder_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        write_osim(load_model(), tmp_path / "missing" / "model.osim")


def test_duplicate_point_names_get_the_segment(exported):
    """A point name on several segments (a joint centre such as AC) is one marker per segment."""
    table = marker_table(exported)
    assert len({name for name, _, _ in table}) == len(table)
    assert ("AC_clavicle", "clavicle", "AC") in table and ("AC_scapula", "scapula", "AC") in table
    assert ("TS", "scapula", "TS") in table


def test_names_the_formats_cannot_hold_are_refused(tmp_path):
    model = load_model()
    thorax = model.segments[0]
    bad = dataclasses.replace(model, segments=(dataclasses.replace(thorax, points={"two words": np.zeros(3)}),)
                              + model.segments[1:])
    for writer in (write_osim, write_biomod):
        with pytest.raises(ModelError, match="two words"):
            writer(bad, tmp_path / "model.txt")
    assert not list(tmp_path.iterdir())


def test_an_unlimited_range_is_written_as_one_turn(tmp_path):
    model = load_model()
    ulna = model.segment("ulna")
    joint = dataclasses.replace(ulna.joint, ranges_rad=np.array([[-np.inf, np.inf]]))
    free = dataclasses.replace(model, segments=tuple(dataclasses.replace(s, joint=joint) if s.name == "ulna" else s
                                                     for s in model.segments))
    turn = f"{-2 * np.pi!r} {2 * np.pi!r}"
    assert f"<range>{turn}</range>" in write_osim(free, tmp_path / "m.osim", coordinates="model").read_text(encoding="utf-8")
    assert f"\t\t{turn}\n" in write_biomod(free, tmp_path / "m.bioMod").read_text(encoding="utf-8")


def test_cli_export_model_writes_and_refuses_to_overwrite(tmp_path, capsys):
    """`exubio export-model MODEL --format osim|biomod --out FILE`: exit 0 and the file; the same
    again without --overwrite: exit 2 naming the file, the file unchanged."""
    from exubio.cli import main

    for fmt, name in (("osim", "m.osim"), ("biomod", "m.bioMod")):
        out = tmp_path / name
        assert main(["-q", "export-model", str(MODEL_PATH), "--format", fmt, "--out", str(out)]) == 0
        before = out.read_bytes()
        assert main(["-q", "export-model", str(MODEL_PATH), "--format", fmt, "--out", str(out)]) == 2
        assert str(out) in capsys.readouterr().err and out.read_bytes() == before
        assert main(["-q", "export-model", str(MODEL_PATH), "--format", fmt, "--out", str(out), "--overwrite"]) == 0
