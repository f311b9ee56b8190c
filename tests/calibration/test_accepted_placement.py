"""A lab's placement accepted once in the protocol (``landmark_offset_mm``): the calibration no
longer names that marker at that distance, still names it well beyond, and names the others as
before (exubio.trust.quality.calibration_reasons)."""
import pytest

from exubio.trust import quality as Q
from exubio.calibration import SCALE_BOUNDS
from exubio.errors import ProtocolError
from exubio.model.load import load_model
from exubio.run.inputs import protocol_for_model
from exubio.io.resources import shipped_file

OFFSETS_MM = {"CLAV_AC": 66.0, "EPI_med": 45.0}


@pytest.fixture
def landmark_reasons(make_report):
    cal = make_report(source="static.c3d", landmark_offsets_mm=OFFSETS_MM)

    def reasons(accepted):
        return [r for r in Q.calibration_reasons(cal, scale_bounds=SCALE_BOUNDS, accepted_offsets_mm=accepted)
                if r.code == "calibration_landmark"]

    return reasons


def test_an_accepted_offset_is_not_named_again_but_a_larger_one_is(landmark_reasons):
    assert {r.message.split("marker ")[1].split(" ")[0] for r in landmark_reasons({})} == {"CLAV_AC", "EPI_med"}
    named = landmark_reasons({"CLAV_AC": 65.0})
    assert [r.message.split("marker ")[1].split(" ")[0] for r in named] == ["EPI_med"]
    beyond = landmark_reasons({"CLAV_AC": 40.0})  # 66 > 40 + 15: still named, with what the protocol accepts
    assert any("CLAV_AC" in r.message and "accepts 40 mm" in r.message for r in beyond)


def test_the_protocol_key_is_read_and_checked(tmp_path):
    text = shipped_file("exubio.protocols", "upper_limb_21.yaml", "protocols").read_text(encoding="utf-8")
    ok = text.replace("CLAV_AC:    {segment: clavicle, point: CLAV_AC, landmark: AC}",
                      "CLAV_AC:    {segment: clavicle, point: CLAV_AC, landmark: AC, landmark_offset_mm: 70}")
    assert ok != text
    (tmp_path / "ok.yaml").write_text(ok, encoding="utf-8")
    protocol = protocol_for_model(load_model(), tmp_path / "ok.yaml")
    assert {m.name: m.landmark_offset_mm for m in protocol.markers}["CLAV_AC"] == 70.0
    bad = text.replace("SEML:       {segment: hand, point: SEML}", "SEML:       {segment: hand, point: SEML, landmark_offset_mm: 5}")
    (tmp_path / "bad.yaml").write_text(bad, encoding="utf-8")
    with pytest.raises(ProtocolError, match="SEML.*landmark_offset_mm.*landmark"):
        protocol_for_model(load_model(), tmp_path / "bad.yaml")
