"""Label errors are found as the whole permutation, not pairs only (exubio.trust.labels): three labels
permuted in a cycle on a real trial checked against its session's static are named once as a
permutation with the relabel that undoes it, and that relabel, applied, leaves no finding. Built
from the real trials of ../shared/data (skipped when absent)."""
import dataclasses
from pathlib import Path

import pytest

from exubio.trust import quality as Q
from exubio.io.trial import read_trial
from exubio.trust.labels import check_trial, pair_distances
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.protocol.labels import relabel_trajectories

C3D = Path(__file__).resolve().parents[3] / "shared" / "data" / "c3d"
pytestmark = [pytest.mark.slow, pytest.mark.skipif(not C3D.is_dir(), reason=f"real data folder {C3D} is absent")]
SESSION = Path(__file__).resolve().parents[2] / "protocols" / "examples" / "kinova_martin_session.yaml"


@pytest.fixture(scope="module")
def session():
    model, protocol = load_model_and_protocol(protocol_path=SESSION)
    static = prepare_targets(read_trial(C3D / "bioptim_exo_kinova_martin_statique.c3d"), protocol)
    ref = pair_distances(static.positions_m, static.marker_names, source="the static")
    return model, protocol, ref, read_trial(C3D / "bioptim_exo_kinova_martin_tete_f3_1.c3d")


def _cycle(traj, labels):
    new = list(traj.labels)
    for k, lab in enumerate(labels):
        new[traj.labels.index(lab)] = labels[(k + 1) % len(labels)]
    return dataclasses.replace(traj, labels=tuple(new))


def _check(model, protocol, ref, traj):
    return check_trial(prepare_targets(traj, protocol), model=model, protocol=protocol,
                       ranges_rad=model.coordinate_ranges_rad, reference=ref)


@pytest.mark.parametrize("cycle", [("EPI_lat", "EPI_med", "DELT"), ("SCAP_AC", "SCAP_BACK", "SCAP_FRONT")])
def test_a_three_label_cycle_is_one_permutation_whose_relabel_fixes_it(session, cycle):
    model, protocol, ref, trial = session
    assert _check(model, protocol, ref, trial) == ()  # the session as recorded (with its relabel) is clean
    bad = _cycle(trial, cycle)
    findings = _check(model, protocol, ref, bad)
    assert [f.kind for f in findings] == ["permutation"], [(f.kind, f.markers) for f in findings]
    f = findings[0]
    assert set(f.markers) == set(cycle) and f.severity == "error"
    fixed = relabel_trajectories(bad, f.relabel)
    assert fixed.labels == trial.labels  # the proposed relabel undoes the cycle exactly
    assert _check(model, protocol, ref, fixed) == ()
    reason = Q.label_reasons(findings)[0]
    assert reason.level == "fail" and "--relabel" in reason.message


def test_a_technical_marker_declared_on_a_joint_axis_is_not_made_rigid_with_the_next_segment(tmp_path):
    """A protocol that ties the technical arm marker ARM to the elbow centre (a point on the elbow
    axis, rigid with the forearm in the model) must not make the real ARM marker look like a label
    that jumps: across segments only landmark markers' declared points are trusted."""
    from exubio.io.resources import shipped_file

    text = shipped_file("exubio.protocols", "upper_limb_21.yaml", "protocols").read_text(encoding="utf-8")
    tied = text.replace("ARM:        {segment: humerus, point: ARM}", "ARM:        {segment: humerus, point: EJC}")
    assert tied != text
    (tmp_path / "axis.yaml").write_text(tied, encoding="utf-8")
    model, protocol = load_model_and_protocol(protocol_path=tmp_path / "axis.yaml")
    targets = prepare_targets(read_trial(C3D / "bioptim_exo_martin_dynamique.c3d"), protocol)
    findings = check_trial(targets, model=model, protocol=protocol, ranges_rad=model.coordinate_ranges_rad)
    assert not [f for f in findings if "ARM" in f.markers], [(f.kind, f.markers) for f in findings]
