"""Tests of exubio.trust.labels: marker-label checks from the protocol and the model.

Simulated trials (exubio.synth.simulate) run everywhere; the real C3D trials of ../shared/data/c3d
(Ipuch/bioptim_exo, MIT; see ../shared/data/SOURCES.md) are skipped when absent. The broken
trials are built here from correct ones: labels exchanged, a label moved onto a marker of another
segment or jumping for part of the trial, a marker moved, another subject's static as reference.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from exubio.trust import label_expectations as LE
from exubio.trust import labels as L
from exubio.calibration import scale_model
from exubio.errors import InputError
from exubio.io.records import decode, to_json
from exubio.model.kinematics import Kinematics
from exubio.run.inputs import protocol_for_model
from exubio.synth.simulate import simulate_trial

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
C3D = Path(__file__).resolve().parents[3] / "shared" / "data" / "c3d"
SESSION = REPO / "protocols" / "examples" / "kinova_martin_session.yaml"
KINOVA = ("kinova_martin_statique", "kinova_martin_aisselle_f3_1", "kinova_martin_dent_f3_1",
          "kinova_martin_manger_f3_1", "kinova_martin_tete_f3_1")


# --------------------------------------------------------------------------------------------
# Fixtures and helpers
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def protocol(model):
    return protocol_for_model(model)


@pytest.fixture(scope="module")
def expect(model, protocol):
    return L.model_expectations(model, protocol)


def positions_of(trajectories, names):
    """(n, k, 3) positions of ``names`` (protocol order) from simulated trajectories."""
    return np.stack([trajectories.positions_m[:, trajectories.labels.index(n)] for n in names], axis=1)


def swapped(pos, names, a, b):
    out = pos.copy()
    i, j = names.index(a), names.index(b)
    out[:, [i, j]] = out[:, [j, i]]
    return out


def check(pos, protocol, model, expect, reference=None):
    return L.check_trial(pos, protocol.marker_names, model=model, protocol=protocol, expectations=expect,
                         reference=reference)


def kinds(findings):
    return [(f.kind, frozenset(f.markers)) for f in findings]


@pytest.fixture(scope="module")
def sim(model, protocol):
    """A simulated abduction trial with 1 mm noise and 10 mm soft-tissue artefact, in the lab frame."""
    trial = simulate_trial(model, "abduction", duration_s=5.0, noise_mm=1.0, sta_mm=10.0, seed=3)
    return positions_of(trial.trajectories, protocol.marker_names)


# --------------------------------------------------------------------------------------------
# Distances and expectations
# --------------------------------------------------------------------------------------------
def test_pair_distances_medians_spreads_and_gaps():
    pos = np.zeros((4, 3, 3))
    pos[:, 1, 0] = [0.10, 0.10, 0.12, 0.30]  # B: 100, 100, 120, 300 mm from A
    pos[:, 2, 1] = 0.05
    pos[2, 2] = np.nan  # C missing in frame 2
    pos[3, 2, 0] = np.inf  # a non-finite sample is a gap too
    pd = L.pair_distances(pos, ("A", "B", "C"), source="t")
    assert pd.names == ("A", "B", "C") and pd.source == "t"
    assert pd.median_m[0, 1] == pytest.approx(0.11) and pd.median_m[1, 0] == pytest.approx(0.11)
    assert pd.spread_m[0, 1] == pytest.approx(np.std([0.10, 0.10, 0.12, 0.30]))
    assert pd.n_frames[0, 2] == 2 and pd.n_frames[0, 1] == 4
    assert pd.median_m[0, 2] == pytest.approx(0.05)
    assert pd.get("A", "C") == pytest.approx(0.05) and np.isnan(pd.get("A", "Z"))
    with pytest.raises(InputError, match="shape"):
        L.pair_distances(pos[:, :2], ("A", "B", "C"))


def _pair_distances_one_marker_at_a_time(pos):
    """The computation pair_distances did before it took every pair at once (marker by marker,
    against all others): the reference its results must equal to the bit."""
    pos = pos.copy()
    pos[~np.isfinite(pos).all(axis=2)] = np.nan
    k = pos.shape[1]
    med, sd, cnt = np.full((k, k), np.nan), np.full((k, k), np.nan), np.zeros((k, k), dtype=int)
    for i in range(k):
        d = np.linalg.norm(pos[:, i:i + 1, :] - pos, axis=2)
        cnt[i] = np.isfinite(d).sum(axis=0)
        seen = cnt[i] > 0
        if seen.any():
            med[i, seen] = np.nanmedian(d[:, seen], axis=0)
            sd[i, seen] = np.nanstd(d[:, seen], axis=0)
    np.fill_diagonal(med, 0.0)
    np.fill_diagonal(sd, 0.0)
    return med, sd, cnt


def test_pair_distances_equal_the_marker_by_marker_computation(sim):
    rng = np.random.default_rng(5)
    gappy = sim.copy()
    gappy[100:180, 3] = np.nan  # a gap
    gappy[::7, 5, 1] = np.nan  # single missing coordinates
    gappy[:, 8] = np.nan  # a marker never seen
    gappy[400:, 9] = np.inf
    lonely = rng.normal(size=(40, 4, 3))
    lonely[:, 2] = np.nan
    lonely[10:, 3] = np.nan  # one pair only (markers 0-1, 0-3 and 1-3 overlap in 10 frames)
    for pos in (sim, gappy, lonely, sim[:1], rng.normal(size=(600, 2, 3))):
        names = tuple(f"M{i}" for i in range(pos.shape[1]))
        pd = L.pair_distances(pos, names)
        med, sd, cnt = _pair_distances_one_marker_at_a_time(pos)
        assert np.array_equal(pd.median_m, med, equal_nan=True)
        assert np.array_equal(pd.spread_m, sd, equal_nan=True)
        assert np.array_equal(pd.n_frames, cnt)


def test_expectations_are_held_by_the_binding_and_equal_a_fresh_computation(model, protocol, expect):
    """The binding computes its expectations once and holds them (the same object on every ask, read-
    only arrays), equal to model_expectations computed afresh; another binding of the same content
    computes its own (no process-wide cache), equal to the first; a moved marker changes them."""
    from exubio.protocol.bind import bind

    binding = bind(model, protocol)
    a = LE.expectations_of(binding)
    assert LE.expectations_of(binding) is a  # held: computed once
    assert a.model is model and a.protocol is protocol
    for name in ("relations", "min_ratio", "rigid", "rigid_model_m", "model_median_m", "ranges_rad"):
        assert np.array_equal(getattr(a, name), getattr(expect, name)), name
        assert not getattr(a, name).flags.writeable, name
    assert [(c.root, c.markers.tolist(), c.coordinates.tolist()) for c in a.chains] == \
        [(c.root, c.markers.tolist(), c.coordinates.tolist()) for c in expect.chains]
    b = LE.expectations_of(bind(model, protocol))
    assert b is not a and np.array_equal(b.relations, a.relations)
    moved = dataclasses.replace(protocol, markers=(dataclasses.replace(
        protocol.markers[0], local_position_m=protocol.markers[0].local_position_m + 0.05),) + protocol.markers[1:])
    assert not np.array_equal(LE.expectations_of(bind(model, moved)).model_median_m, a.model_median_m)


def test_side_relations_hold_in_postures_not_sampled(model, protocol, expect):
    """The relations come from one posture sample; in 2000 other postures within the same ranges
    none is reversed (the 30 % margin absorbs what the sample missed)."""
    kin = Kinematics(model)
    pts = kin.points(L.sample_postures(model.coordinate_ranges_rad, 2000, seed=7),
                     kin.point_set([(m.segment, m.local_position_m) for m in protocol.markers]))
    a, x, y = expect.relations.T
    d_ax = np.linalg.norm(pts[:, a] - pts[:, x], axis=2)
    d_ay = np.linalg.norm(pts[:, a] - pts[:, y], axis=2)
    assert len(expect.relations) > 100
    assert np.all(d_ay > d_ax)
    assert np.all(expect.min_ratio >= L.SIDE_RATIO_MIN)
    rel = {(r.marker, r.nearer, r.farther) for r in expect.side_relations}
    assert ("ARM", "DELT", "ELB") in rel  # the upper arm's markers are nearer each other than the olecranon
    # the model cannot order the styloids and the metacarpal heads over the wrist's range of motion
    assert ("MET5", "ULNA", "RADIUS") not in rel and ("MET2", "RADIUS", "ULNA") not in rel


def test_rigid_pairs_and_chains_come_from_the_model(protocol, expect):
    names, segs = expect.names, expect.segments
    rigid = {frozenset((names[i], names[j])) for i, j in expect.rigid}
    same = {frozenset((a, b)) for a in names for b in names if a != b and segs[names.index(a)] == segs[names.index(b)]}
    assert same <= rigid
    # the elbow axis runs through the epicondyles: their distance to any point of the ulna is fixed
    assert frozenset(("EPI_lat", "ULNA")) in rigid and frozenset(("EPI_med", "ELB")) in rigid
    assert frozenset(("EPI_lat", "RADIUS")) not in rigid  # pronation moves the radius
    chains = {c.root: {names[m] for m in c.markers} for c in expect.chains}
    assert chains["ulna"] == {"ULNA", "ELB", "RADIUS", "MET2", "MET5", "SEML"}
    assert chains["radius"] == {"RADIUS", "MET2", "MET5", "SEML"}
    assert "hand" not in chains  # one segment: nothing to fit


def test_ranges_are_checked_and_unbounded_ones_sampled_over_a_turn(model, protocol):
    with pytest.raises(InputError, match=r"ranges_rad must have shape \(13, 2\)"):
        L.model_expectations(model, protocol, np.zeros((12, 2)))
    with pytest.raises(InputError, match="lower <= upper"):
        L.model_expectations(model, protocol, np.tile([1.0, -1.0], (13, 1)))
    q = L.sample_postures(np.tile([-np.inf, np.inf], (13, 1)), 500)
    assert q.min() >= -np.pi and q.max() <= np.pi and q.max() > 3.0


# --------------------------------------------------------------------------------------------
# Simulated trials (no shared data needed)
# --------------------------------------------------------------------------------------------
def test_clean_simulated_trial_has_no_finding(sim, model, protocol, expect):
    assert check(sim, protocol, model, expect) == ()
    assert check(sim[::2], protocol, model, expect, reference=L.pair_distances(sim, protocol.marker_names)) == ()


@pytest.mark.parametrize("a, b", [("MET2", "MET5"), ("ARM", "MET2"), ("RADIUS", "ULNA")])
def test_simulated_swap_is_named(sim, model, protocol, expect, a, b):
    findings = check(swapped(sim, protocol.marker_names, a, b), protocol, model, expect)
    assert kinds(findings) == [("swap", frozenset((a, b)))], findings
    f = findings[0]
    assert f.severity == "error" and " mm" in f.evidence and "look swapped" in f.evidence


def test_epicondyle_swap_against_the_static_reference(sim, model, protocol, expect):
    names = protocol.marker_names
    ref = L.pair_distances(sim, names, source="static")
    findings = check(swapped(sim, names, "EPI_lat", "EPI_med"), protocol, model, expect, reference=ref)
    assert kinds(findings) == [("swap", frozenset(("EPI_lat", "EPI_med")))]


def test_label_jumping_for_part_of_the_trial(sim, model, protocol, expect):
    names = protocol.marker_names
    pos = sim.copy()
    n = len(pos)
    pos[n // 3:n // 3 + n // 5] = swapped(pos, names, "DELT", "SEML")[n // 3:n // 3 + n // 5]
    findings = check(pos, protocol, model, expect)
    assert ("jump", frozenset({"DELT"})) in kinds(findings) and ("jump", frozenset({"SEML"})) in kinds(findings)
    assert "SD" in next(f for f in findings if f.kind == "jump").evidence


def test_another_subjects_reference(model, protocol, expect, sim):
    """A reference from a body whose girdle and upper arm are 25 % larger: one other_subject finding."""
    big = scale_model(model, {"clavicle": 1.25, "scapula": 1.25, "humerus": 1.25})
    other = positions_of(simulate_trial(big, "abduction", duration_s=2.0, seed=4).trajectories, protocol.marker_names)
    ref = L.pair_distances(other, protocol.marker_names, source="big static")
    findings = check(sim, protocol, model, expect, reference=ref)
    assert [f.kind for f in findings] == ["other_subject"], findings
    assert "big static" in findings[0].evidence


def test_input_order_extra_markers_and_targets(sim, model, protocol, expect):
    """Markers may come in any order, with extra ones; a MarkerTargets works as well."""
    from exubio.types import MarkerTargets

    names = list(protocol.marker_names)
    pos = swapped(sim, names, "ARM", "MET2")
    order = np.random.default_rng(0).permutation(len(names))
    extra = np.full((len(pos), 1, 3), 0.5)
    mixed = np.concatenate([pos[:, order], extra], axis=1)
    f1 = L.check_trial(mixed, [names[i] for i in order] + ["Table"], model=model, protocol=protocol, expectations=expect)
    targets = MarkerTargets(time_s=np.arange(len(pos)) / 100.0, marker_names=tuple(names), positions_m=pos,
                            velocities_m_s=np.zeros_like(pos), accelerations_m_s2=np.zeros_like(pos))
    f2 = L.check_trial(targets, model=model, protocol=protocol, expectations=expect)
    assert kinds(f1) == kinds(f2) == [("swap", frozenset(("ARM", "MET2")))]
    with pytest.raises(InputError, match="marker_names"):
        L.check_trial(pos, model=model, protocol=protocol, expectations=expect)


def test_findings_are_typed_and_printable():
    f = L.LabelFinding("swap", ("A", "B"), "A and B look swapped: 107 mm", "error")
    with pytest.raises(dataclasses.FrozenInstanceError):
        f.kind = "side"  # type: ignore[misc]
    assert to_json(f) == {"kind": "swap", "markers": ["A", "B"], "evidence": "A and B look swapped: 107 mm",
                          "severity": "error", "relabel": {"A": "B", "B": "A"}}  # a swap carries the relabel that undoes it
    assert decode(L.LabelFinding, to_json(f)) == f
    side = L.LabelFinding("side", ("A",), "A is on the wrong side", "warning")
    assert "relabel" not in to_json(side) and decode(L.LabelFinding, to_json(side)) == side  # no relabel: no key
    assert L.format_findings([f], source="t.c3d") == "t.c3d: error [swap] A, B: A and B look swapped: 107 mm"
    assert "no finding" in L.format_findings([])


# --------------------------------------------------------------------------------------------
# Real C3D trials (../shared/data/c3d)
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def real():
    """Prepared targets of the shared C3D trials, by file stem and protocol file."""
    if not C3D.is_dir():
        pytest.skip(f"real data folder {C3D} is absent")
    from exubio.io.trial import read_trial
    from exubio.prep.targets import prepare_targets

    cache = {}

    def get(stem, protocol):
        key = (stem, protocol.source)
        if key not in cache:
            cache[key] = prepare_targets(read_trial(C3D / f"bioptim_exo_{stem}.c3d"), protocol)
        return cache[key]

    return get


def reference_of(targets, name):
    return L.pair_distances(targets.positions_m, targets.marker_names, source=name)


@pytest.mark.parametrize("stem, ref", [("martin_statique", None), ("martin_dynamique", "martin_statique"),
                                       ("F0_boire_05", None)])
def test_correctly_labelled_real_trials_have_no_finding(real, model, protocol, expect, stem, ref):
    reference = reference_of(real(ref, protocol), ref) if ref else None
    findings = L.check_trial(real(stem, protocol), model=model, protocol=protocol, expectations=expect,
                             reference=reference)
    assert findings == (), L.format_findings(findings)


@pytest.mark.parametrize("stem", KINOVA)
def test_kinova_session_has_radius_and_ulna_swapped(real, model, protocol, expect, stem):
    ref = None if stem == KINOVA[0] else reference_of(real(KINOVA[0], protocol), KINOVA[0])
    findings = L.check_trial(real(stem, protocol), model=model, protocol=protocol, expectations=expect, reference=ref)
    assert kinds(findings) == [("swap", frozenset(("RADIUS", "ULNA")))], L.format_findings(findings)
    assert "MET5 is 10" in findings[0].evidence and "from ULNA" in findings[0].evidence  # 107-109 mm


@pytest.mark.parametrize("stem", KINOVA)
def test_kinova_session_protocol_with_relabel_has_no_finding(real, model, stem):
    session = protocol_for_model(model, SESSION)
    assert dict(session.relabel) == {"RADIUS": "ULNA", "ULNA": "RADIUS"}
    ref = None if stem == KINOVA[0] else reference_of(real(KINOVA[0], session), KINOVA[0])
    findings = L.check_trial(real(stem, session), model=model, protocol=session, reference=ref)
    assert findings == (), L.format_findings(findings)


@pytest.mark.parametrize("a, b, with_ref", [("MET2", "MET5", True), ("MET2", "MET5", False), ("ARM", "MET2", False),
                                            ("EPI_lat", "EPI_med", True), ("SCAP_AA", "SCAP_IA", True)])
def test_real_trial_with_two_labels_exchanged(real, model, protocol, expect, a, b, with_ref):
    names = protocol.marker_names
    ref = reference_of(real("martin_statique", protocol), "martin_statique") if with_ref else None
    pos = swapped(real("martin_dynamique", protocol).positions_m, names, a, b)
    findings = check(pos, protocol, model, expect, reference=ref)
    assert kinds(findings) == [("swap", frozenset((a, b)))], L.format_findings(findings)


def test_real_label_moved_to_another_segment(real, model, protocol, expect):
    """The ARM label on a hand marker (the upper-arm marker itself unlabelled)."""
    names = protocol.marker_names
    pos = real("martin_dynamique", protocol).positions_m.copy()
    pos[:, names.index("ARM")] = pos[:, names.index("SEML")] + [0.01, 0.0, 0.0]
    findings = check(pos, protocol, model, expect)
    assert kinds(findings) == [("wrong_segment", frozenset({"ARM"}))], L.format_findings(findings)
    assert "a marker of the hand" in findings[0].evidence


def test_real_marker_moved(real, model, protocol, expect):
    names = protocol.marker_names
    ref = reference_of(real("martin_statique", protocol), "martin_statique")
    pos = real("martin_dynamique", protocol).positions_m.copy()
    pos[:, names.index("EPI_lat")] += [0.0, 0.0, -0.04]  # 40 mm towards the medial epicondyle
    findings = check(pos, protocol, model, expect, reference=ref)
    assert kinds(findings) == [("distance", frozenset({"EPI_lat"}))], L.format_findings(findings)
    assert findings[0].severity == "warning" and "reference" in findings[0].evidence


def test_real_static_of_another_subject(real, model, protocol, expect):
    ref = reference_of(real("martin_statique", protocol), "martin_statique")
    f0 = real("F0_boire_05", protocol)
    findings = L.check_trial(f0, model=model, protocol=protocol, expectations=expect, reference=ref)
    assert [f.kind for f in findings] == ["other_subject"], L.format_findings(findings)
    assert "martin_statique" in findings[0].evidence and "3 segments" in findings[0].evidence
    # the same subject in another session (markers re-placed) is not another subject
    session = protocol_for_model(model, SESSION)
    kin = L.check_trial(real(KINOVA[0], session), model=model, protocol=session,
                        reference=reference_of(real("martin_statique", session), "martin_statique"))
    assert kin == (), L.format_findings(kin)
