"""Tests of exubio.protocol.load and .labels: loading and validating protocol YAML files, matching trial labels."""
from __future__ import annotations

import logging
import textwrap
from pathlib import Path

import numpy as np
import pytest

from exubio.errors import InputError, ProtocolError
from exubio.protocol.labels import LabelMatch, resolve_labels
from exubio.protocol.load import check_keys, load_protocol, read_yaml
from exubio.types import ThoraxFrameSpec

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "protocols" / "upper_limb_21.yaml"
SEGMENTS = ("thorax", "clavicle", "scapula", "humerus", "ulna", "radius", "hand")

_POINT_NAMES = {
    "thorax": ["MAN", "XYP", "C7", "T10"],
    "clavicle": ["CLAV_SC", "CLAV_AC"],
    "scapula": ["SCAP_Cor", "SCAP_AA", "SCAP_AC", "SCAP_IA", "SCAP_BACK", "SCAP_FRONT", "GH"],
    "humerus": ["ARM", "DELT", "EPI_lat", "EPI_med"],
    "ulna": ["ULNA", "ELB"],
    "radius": ["RADIUS"],
    "hand": ["MET2", "MET5", "SEML"],
}
# synthetic model points: distinct, recognisable positions (m)
MODEL_POINTS = {
    seg: {p: np.array([0.01 * i, 0.02 * k, -0.003 * i * k]) for k, p in enumerate(points, start=1)}
    for i, (seg, points) in enumerate(_POINT_NAMES.items(), start=1)
}
C3D_LABELS_STATIC = (
    "C7", "T10", "MAN", "XYP", "CLAV_SC", "CLAV_AC", "SCAP_BACK", "SCAP_IA", "SCAP_AA", "SCAP_AC",
    "SCAP_FRONT", "SCAP_Cor", "ARM", "EPI_med", "EPI_lat", "DELT", "ULNA", "RADIUS", "SEML", "MET5",
    "MET2",
)

MINIMAL = """\
schema_version: 1
name: mini
thorax_frame: {ij: IJ, px: PX, c7: C7, t8: T8}
markers:
  ARM: {segment: humerus, local_position_mm: [10, -200, 30]}
"""


def write(tmp_path: Path, text: str, name: str = "p.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def load(path: Path, **kw):
    kw.setdefault("segments", SEGMENTS)
    kw.setdefault("model_points", MODEL_POINTS)
    return load_protocol(path, **kw)


# --------------------------------------------------------------------------------------------
# The shipped protocol
# --------------------------------------------------------------------------------------------
def test_shipped_upper_limb_21():
    prot = load(SHIPPED)
    assert prot.name == "upper_limb_21"
    assert prot.source == str(SHIPPED)
    assert prot.thorax_frame == ThoraxFrameSpec(ij="MAN", px="XYP", c7="C7", t8="T10")
    assert prot.cutoff_hz == "auto" and prot.filter_order == 2
    assert prot.default_stiffness_n_per_m == 1500.0 and prot.default_damping_ns_per_m == 300.0
    required = [m for m in prot.markers if not m.optional]
    assert len(required) == 17
    assert [m.name for m in prot.markers if m.optional] == ["ELB"]
    assert all(m.segment != "thorax" for m in prot.markers)
    for m in prot.markers:
        np.testing.assert_array_equal(m.local_position_m, MODEL_POINTS[m.segment][m.name])
        assert m.local_position_m.dtype == np.float64
    np.testing.assert_allclose(prot.weights, 1.0)
    by_segment = {}
    for m in prot.markers:
        by_segment.setdefault(m.segment, []).append(m.name)
    assert by_segment == {
        "clavicle": ["CLAV_SC", "CLAV_AC"],
        "scapula": ["SCAP_Cor", "SCAP_AA", "SCAP_AC", "SCAP_IA", "SCAP_BACK", "SCAP_FRONT"],
        "humerus": ["ARM", "DELT", "EPI_lat", "EPI_med"],
        "ulna": ["ULNA", "ELB"],
        "radius": ["RADIUS"],
        "hand": ["MET2", "MET5", "SEML"],
    }


def test_shipped_matches_static_trial_labels():
    prot = load(SHIPPED)
    match = resolve_labels(prot, C3D_LABELS_STATIC, source="static.c3d")
    assert match.unused == ()
    assert match.columns["ELB"] is None
    assert match.thorax_columns == {"ij": 2, "px": 3, "c7": 0, "t8": 1}
    assert {C3D_LABELS_STATIC[c] for n, c in match.columns.items() if c is not None} == set(
        C3D_LABELS_STATIC[4:]
    )


# --------------------------------------------------------------------------------------------
# Format features
# --------------------------------------------------------------------------------------------
def test_minimal_defaults_and_mm_conversion(tmp_path):
    prot = load(write(tmp_path, MINIMAL), model_points=None)
    (arm,) = prot.markers
    np.testing.assert_allclose(arm.local_position_m, [0.010, -0.200, 0.030])
    assert arm.stiffness_n_per_m == 1500.0 and arm.damping_ns_per_m == 300.0 and not arm.optional
    assert prot.cutoff_hz == 2.0 and prot.filter_order == 2


def test_full_marker_keys_identity_frame_and_no_filter(tmp_path):
    path = write(tmp_path, """\
        schema_version: 1
        name: full
        description: every key
        thorax_frame: identity
        filter: none
        defaults: {stiffness_n_per_m: 1000, damping_ns_per_m: 100}
        markers:
          IJ: {segment: thorax}
          ARM: {segment: humerus, local_position_mm: [0, -100, 0], aliases: [RARM, R_ARM],
                stiffness_n_per_m: 500, damping_ns_per_m: 0, optional: true}
          EL: {segment: humerus, point: EPI_lat}
        """)
    prot = load(path)
    assert prot.thorax_frame.is_identity
    assert prot.cutoff_hz is None
    assert prot.marker_names == ("ARM", "EL")  # thorax marker not tracked
    arm, el = prot.markers
    assert arm.aliases == ("RARM", "R_ARM") and arm.optional
    assert arm.stiffness_n_per_m == 500.0 and arm.damping_ns_per_m == 0.0
    assert el.stiffness_n_per_m == 1000.0 and el.damping_ns_per_m == 100.0
    np.testing.assert_allclose(prot.weights, [0.5, 1.0])


def test_name_defaults_to_file_stem(tmp_path):
    prot = load(write(tmp_path, MINIMAL.replace("name: mini\n", ""), name="lab_set.yaml"))
    assert prot.name == "lab_set"


def test_filter_settings(tmp_path):
    prot = load(write(tmp_path, MINIMAL + "filter: {cutoff_hz: 6, order: 4}\n"))
    assert prot.cutoff_hz == 6.0 and prot.filter_order == 4


@pytest.mark.parametrize("text", ["auto", "Auto", "'auto'"])
def test_filter_cutoff_auto(tmp_path, text):
    prot = load(write(tmp_path, MINIMAL + f"filter: {{cutoff_hz: {text}, order: 2}}\n"))
    assert prot.cutoff_hz == "auto" and prot.filter_order == 2


@pytest.mark.parametrize("value", ["fast", "'2 Hz'", "[2, 6]", "true", "0", "-2", ".nan", "null"])
def test_filter_cutoff_bad_value_is_one_clear_error(tmp_path, value):
    path = write(tmp_path, MINIMAL + f"filter: {{cutoff_hz: {value}}}\n")
    with pytest.raises(ProtocolError) as exc:
        load(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: filter.cutoff_hz is ")
    assert msg.endswith("expected a number > 0 (Hz) or 'auto' (a cut-off per marker by Winter's residual analysis)")


# --------------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------------
def test_unknown_marker_key_names_path_file_and_suggestion(tmp_path):
    path = write(tmp_path, MINIMAL.replace("[10, -200, 30]}", "[10, -200, 30], stifness_n_per_m: 3}"))
    with pytest.raises(ProtocolError) as exc:
        load(path)
    msg = str(exc.value)
    assert str(path) in msg
    assert "markers.ARM.stifness_n_per_m" in msg
    assert "did you mean 'stiffness_n_per_m'" in msg
    assert "'local_position_mm'" in msg and "'optional'" in msg  # the valid keys are listed


@pytest.mark.parametrize(
    "extra, where",
    [
        ("colour: red\n", "colour"),
        ("filter: {cutoff: 2}\n", "filter.cutoff"),
        ("defaults: {stiffness: 2}\n", "defaults.stiffness"),
    ],
)
def test_unknown_keys_at_every_level(tmp_path, extra, where):
    with pytest.raises(ProtocolError, match=rf"unknown key '{where}'"):
        load(write(tmp_path, MINIMAL + extra))


def test_unknown_thorax_frame_key(tmp_path):
    path = write(tmp_path, MINIMAL.replace("t8: T8}", "t8: T8, t10: T10}"))
    with pytest.raises(ProtocolError, match=r"unknown key 'thorax_frame.t10'.*'ij', 'px', 'c7', 't8'"):
        load(path)


def test_unknown_segment_lists_valid_segments(tmp_path):
    path = write(tmp_path, MINIMAL.replace("segment: humerus", "segment: humerous"))
    with pytest.raises(ProtocolError) as exc:
        load(path)
    msg = str(exc.value)
    assert "markers.ARM.segment" in msg and "'humerous'" in msg and "did you mean 'humerus'" in msg
    assert all(s in msg for s in SEGMENTS)


def test_unknown_point_lists_segment_points(tmp_path):
    path = write(tmp_path, MINIMAL.replace("local_position_mm: [10, -200, 30]", "point: EPI_lateral"))
    with pytest.raises(ProtocolError) as exc:
        load(path)
    msg = str(exc.value)
    assert "markers.ARM.point" in msg and "'EPI_lateral'" in msg and "'humerus'" in msg
    assert all(p in msg for p in _POINT_NAMES["humerus"])


def test_point_without_model_points(tmp_path):
    path = write(tmp_path, MINIMAL.replace("local_position_mm: [10, -200, 30]", "point: ARM"))
    with pytest.raises(ProtocolError, match="no model points were given"):
        load(path, model_points=None)


@pytest.mark.parametrize(
    "spec, fragment",
    [
        ("{segment: humerus}", "needs its position"),
        ("{segment: humerus, point: ARM, local_position_mm: [1, 2, 3]}", "exactly one"),
        ("{segment: humerus, local_position_mm: [1, 2]}", "list of 3 numbers"),
        ("{segment: humerus, local_position_mm: [1, 2, x]}", "list of 3 numbers"),
        ("{local_position_mm: [1, 2, 3]}", "segment is missing"),
        ("{segment: humerus, point: ARM, stiffness_n_per_m: 0}", "stiffness_n_per_m is 0; expected a number > 0"),
        ("{segment: humerus, point: ARM, stiffness_n_per_m: -5}", "expected a number > 0"),
        ("{segment: humerus, point: ARM, damping_ns_per_m: -1}", "expected a number >= 0"),
        ("{segment: humerus, point: ARM, stiffness_n_per_m: stiff}", "must be a finite number"),
        ("{segment: humerus, point: ARM, optional: maybe}", "optional must be true or false"),
        ("{segment: humerus, point: ARM, aliases: RARM}", "aliases must be a list"),
        ("[humerus]", "must be a mapping"),
    ],
)
def test_bad_marker_values(tmp_path, spec, fragment):
    path = write(tmp_path, MINIMAL.replace("{segment: humerus, local_position_mm: [10, -200, 30]}", spec))
    with pytest.raises(ProtocolError) as exc:
        load(path)
    assert fragment in str(exc.value)
    assert str(path) in str(exc.value)
    assert "markers.ARM" in str(exc.value)


@pytest.mark.parametrize(
    "replace, fragment",
    [
        (("schema_version: 1\n", ""), "missing key 'schema_version'"),
        (("schema_version: 1", "schema_version: 2"), "schema_version is 2"),
        (("schema_version: 1", "schema_version: '1'"), "schema_version is '1'"),
        (("thorax_frame: {ij: IJ, px: PX, c7: C7, t8: T8}\n", ""), "missing key 'thorax_frame'"),
        (("{ij: IJ, px: PX, c7: C7, t8: T8}", "{ij: IJ, px: PX, c7: C7}"), "thorax_frame.t8 is missing"),
        (("{ij: IJ, px: PX, c7: C7, t8: T8}", "{ij: IJ, px: PX, c7: C7, t8: IJ}"), "four different labels"),
        (("{ij: IJ, px: PX, c7: C7, t8: T8}", "isb"), "expected 'identity'"),
        (("name: mini\n", "name: mini\nfilter: {cutoff_hz: 0}\n"), "filter.cutoff_hz is 0"),
        (("name: mini\n", "name: mini\nfilter: {cutoff_hz: -2}\n"), "filter.cutoff_hz is -2"),
        (("name: mini\n", "name: mini\nfilter: {order: 0}\n"), "filter.order"),
        (("name: mini\n", "name: mini\nfilter: lowpass\n"), "filter must be"),
        (("name: mini\n", "name: mini\ndefaults: {stiffness_n_per_m: 0}\n"), "defaults.stiffness_n_per_m"),
        (("name: mini\n", "name: mini\ndefaults: {damping_ns_per_m: -1}\n"), "defaults.damping_ns_per_m"),
    ],
)
def test_bad_top_level(tmp_path, replace, fragment):
    path = write(tmp_path, MINIMAL.replace(*replace))
    with pytest.raises(ProtocolError) as exc:
        load(path)
    assert fragment in str(exc.value)
    assert str(path) in str(exc.value)


def test_duplicate_aliases_across_markers(tmp_path):
    path = write(tmp_path, MINIMAL + """\
  ELBOW: {segment: humerus, local_position_mm: [0, 0, 0], aliases: [EL, RARM]}
  WRIST: {segment: radius, local_position_mm: [0, 0, 0], aliases: [RARM]}
""")
    with pytest.raises(ProtocolError, match="'RARM' of marker 'WRIST' is already used by marker 'ELBOW'"):
        load(path)


def test_alias_equal_to_other_marker_name(tmp_path):
    path = write(tmp_path, MINIMAL + "  ELBOW: {segment: humerus, local_position_mm: [0, 0, 0], aliases: [ARM]}\n")
    with pytest.raises(ProtocolError, match="already used by marker 'ARM'"):
        load(path)


def test_duplicate_yaml_key_is_caught(tmp_path):
    path = write(tmp_path, MINIMAL + "  ARM: {segment: humerus, local_position_mm: [0, 0, 0]}\n")
    with pytest.raises(ProtocolError, match=r"key 'ARM' appears twice .*lines 5 and 6"):
        load(path)


def test_frame_landmark_must_not_be_tracked(tmp_path):
    path = write(tmp_path, MINIMAL.replace("c7: C7", "c7: ARM"))
    with pytest.raises(ProtocolError, match="thorax_frame.c7 is 'ARM'.*segment 'humerus'"):
        load(path)


def test_only_thorax_markers_is_an_error(tmp_path):
    path = write(tmp_path, MINIMAL.replace("segment: humerus, local_position_mm: [10, -200, 30]", "segment: thorax"))
    with pytest.raises(ProtocolError, match="no tracked marker"):
        load(path)


def test_missing_file(tmp_path):
    path = tmp_path / "nope.yaml"
    with pytest.raises(ProtocolError, match=rf"{path}: file not found"):
        load(path)


@pytest.mark.parametrize("text, fragment", [("a: [1, 2\n", "not valid YAML"), ("- 1\n- 2\n", "expected a mapping"),
                                            ("", "expected a mapping")])
def test_not_yaml_or_not_mapping(tmp_path, text, fragment):
    path = write(tmp_path, text)
    with pytest.raises(ProtocolError) as exc:
        load(path)
    assert str(path) in str(exc.value) and fragment in str(exc.value)


def test_read_yaml_and_check_keys_take_the_error_class(tmp_path):
    from exubio.errors import ModelError

    with pytest.raises(ModelError, match="file not found"):
        read_yaml(tmp_path / "m.yaml", error=ModelError)
    with pytest.raises(ModelError, match=r"m.yaml: unknown key 'segments.arm.mas' \(did you mean 'mass'\?\)"):
        check_keys({"mas": 1}, ("mass", "com"), where="segments.arm", source="m.yaml", error=ModelError)


# --------------------------------------------------------------------------------------------
# resolve_labels
# --------------------------------------------------------------------------------------------
ALIASES = """\
schema_version: 1
thorax_frame: {ij: IJ, px: PX, c7: C7, t8: T8}
markers:
  ARM: {segment: humerus, local_position_mm: [0, 0, 0], aliases: [RARM, R_ARM]}
  ELB: {segment: ulna, local_position_mm: [0, 0, 0], optional: true}
  HAND: {segment: hand, local_position_mm: [0, 0, 0]}
"""


def test_resolve_by_name_alias_optional_and_unused(tmp_path):
    prot = load(write(tmp_path, ALIASES))
    labels = ("C7", "R_ARM", "HAND", "IJ", "EXTRA", "PX", "T8", "*22")
    match = resolve_labels(prot, labels, source="trial.c3d")
    assert isinstance(match, LabelMatch)
    assert match.columns == {"ARM": 1, "ELB": None, "HAND": 2}
    assert list(match.columns) == list(prot.marker_names)
    assert match.thorax_columns == {"ij": 3, "px": 5, "c7": 0, "t8": 6}
    assert match.unused == ("EXTRA", "*22")


def test_resolve_prefers_name_then_first_alias(tmp_path, caplog):
    prot = load(write(tmp_path, ALIASES))
    labels = ("R_ARM", "RARM", "HAND", "IJ", "PX", "C7", "T8")
    with caplog.at_level(logging.WARNING, logger="exubio.protocol.labels"):
        match = resolve_labels(prot, labels)
    assert match.columns["ARM"] == 1  # RARM comes before R_ARM in the aliases
    assert match.unused == ("R_ARM",)
    assert "also as 'R_ARM'" in caplog.text
    assert resolve_labels(prot, ("ARM", "RARM", "HAND", "IJ", "PX", "C7", "T8")).columns["ARM"] == 0


def test_resolve_missing_marker_names_it_file_and_labels(tmp_path):
    prot = load(write(tmp_path, ALIASES))
    labels = ("HAND", "IJ", "PX", "C7", "T8")
    with pytest.raises(InputError) as exc:
        resolve_labels(prot, labels, source="trial.c3d")
    msg = str(exc.value)
    assert msg.startswith("trial.c3d:")
    assert "'ARM' (aliases ['RARM', 'R_ARM'])" in msg
    assert "ELB" not in msg  # optional
    assert str(list(labels)) in msg


def test_resolve_missing_thorax_landmark(tmp_path):
    prot = load(write(tmp_path, ALIASES))
    with pytest.raises(InputError, match=r"'T8' \(thorax_frame.t8\)"):
        resolve_labels(prot, ("ARM", "HAND", "IJ", "PX", "C7"), source="trial.c3d")


# --------------------------------------------------------------------------------------------
# relabel and extends
# --------------------------------------------------------------------------------------------
SESSION_EXAMPLE = REPO / "protocols" / "examples" / "kinova_martin_session.yaml"


def test_relabel_defaults_to_nothing_and_is_read(tmp_path):
    assert dict(load(SHIPPED).relabel) == {}
    prot = load(write(tmp_path, ALIASES + "relabel: {HAND: RARM, RARM: HAND}\n"))
    assert dict(prot.relabel) == {"HAND": "RARM", "RARM": "HAND"}
    with pytest.raises(TypeError):
        prot.relabel["X"] = "Y"  # read-only


def test_relabel_applies_before_matching(tmp_path):
    prot = load(write(tmp_path, ALIASES + "relabel: {HAND: ARM, ARM: HAND, T8: PX, PX: T8}\n"))
    labels = ("ARM", "HAND", "IJ", "PX", "C7", "T8", "EXTRA")
    match = resolve_labels(prot, labels, source="trial.c3d")
    assert match.columns == {"ARM": 1, "ELB": None, "HAND": 0}  # the columns are exchanged
    assert match.thorax_columns == {"ij": 2, "px": 5, "c7": 4, "t8": 3}
    assert match.unused == ("EXTRA",)
    # a label the relabel does not name is untouched; a missing marker lists the labels as given
    with pytest.raises(InputError, match=r"the trial has \['HAND', 'IJ', 'PX', 'C7', 'T8'\] \(read as "):
        resolve_labels(prot, ("HAND", "IJ", "PX", "C7", "T8"), source="trial.c3d")


def test_relabel_that_would_duplicate_a_trial_label(tmp_path):
    path = write(tmp_path, ALIASES + "relabel: {RARM: ARM}\n")
    prot = load(path)
    assert resolve_labels(prot, ("RARM", "HAND", "IJ", "PX", "C7", "T8")).columns["ARM"] == 0  # a renaming
    with pytest.raises(ProtocolError) as exc:
        resolve_labels(prot, ("RARM", "ARM", "HAND", "IJ", "PX", "C7", "T8"), source="trial.c3d")
    msg = str(exc.value)
    assert str(path) in msg and "relabel.RARM" in msg and "trial.c3d" in msg and "'ARM'" in msg


@pytest.mark.parametrize(
    "relabel, fragment",
    [
        ("[RADIUS, ULNA]", "relabel must be a mapping"),
        ("RADIUS", "relabel must be a mapping"),
        ("{RADIUS: 3}", "relabel.RADIUS: trial labels and the labels they are read as must be non-empty strings"),
        ("{RADIUS: RADIUS}", "relabel.RADIUS: reads 'RADIUS' as itself"),
        ("{RADIUS: ULNA, WRIST: ULNA}", "relabel.WRIST: 'WRIST' and 'RADIUS' would both be read as 'ULNA'"),
    ],
)
def test_bad_relabel(tmp_path, relabel, fragment):
    path = write(tmp_path, MINIMAL + f"relabel: {relabel}\n")
    with pytest.raises(ProtocolError) as exc:
        load(path)
    assert fragment in str(exc.value) and str(path) in str(exc.value)


def test_extends_a_file_next_to_it(tmp_path):
    write(tmp_path, ALIASES.replace("schema_version: 1\n", "schema_version: 1\nname: base\nfilter: {cutoff_hz: 6}\n"),
          name="base.yaml")
    session = write(tmp_path, "schema_version: 1\nextends: base.yaml\nfilter: none\nrelabel: {A: B, B: A}\n",
                    name="session.yaml")
    prot = load(session)
    assert prot.name == "base"  # keys the session file does not give come from the base
    assert prot.marker_names == ("ARM", "ELB", "HAND")
    assert prot.cutoff_hz is None  # a key it gives replaces the base's
    assert dict(prot.relabel) == {"A": "B", "B": "A"}
    assert prot.source == str(session)


def test_extends_a_shipped_protocol_by_name(tmp_path):
    for ref in ("upper_limb_21.yaml", "upper_limb_21"):
        prot = load(write(tmp_path, f"schema_version: 1\nextends: {ref}\nrelabel: {{RADIUS: ULNA, ULNA: RADIUS}}\n"))
        shipped = load(SHIPPED)
        assert prot.marker_names == shipped.marker_names and prot.thorax_frame == shipped.thorax_frame
        assert dict(prot.relabel) == {"RADIUS": "ULNA", "ULNA": "RADIUS"}


def test_uncertainty_model_is_found_next_to_the_file_that_names_it(tmp_path):
    """``uncertainty_model:`` is resolved against the folder of the protocol file that gives the key (a
    base file in another folder keeps its own); absent it is None (the shipped model)."""
    lab = tmp_path / "lab"
    lab.mkdir()
    (lab / "u.json").write_text("{}")
    write(lab, ALIASES.replace("schema_version: 1\n", "schema_version: 1\nuncertainty_model: u.json\n"), name="base.yaml")
    session = write(tmp_path, "schema_version: 1\nextends: lab/base.yaml\n", name="session.yaml")
    assert load(session).uncertainty_model == str((lab / "u.json").resolve())
    assert load(write(tmp_path, ALIASES, name="plain.yaml")).uncertainty_model is None


@pytest.mark.parametrize("value, fragment", [("missing.json", "'missing.json' not found"),
                                             ("[a, b]", "must name a JSON file")])
def test_a_bad_uncertainty_model_names_the_file_and_the_key(tmp_path, value, fragment):
    path = write(tmp_path, ALIASES.replace("schema_version: 1\n", f"schema_version: 1\nuncertainty_model: {value}\n"))
    with pytest.raises(ProtocolError) as exc:
        load(path)
    assert fragment in str(exc.value) and str(path) in str(exc.value) and "uncertainty_model" in str(exc.value)


def test_a_protocol_knows_the_files_it_was_read_from(tmp_path):
    """Its own first, then each file of its extends chain that gives it a key: what a result made with
    it depends on (exubio.run.resume)."""
    (tmp_path / "lab").mkdir()
    write(tmp_path / "lab", "schema_version: 1\nextends: upper_limb_21\nfilter: {cutoff_hz: 6}\n", name="base.yaml")
    session = write(tmp_path, "schema_version: 1\nextends: lab/base.yaml\n", name="s.yaml")
    files = [Path(f) for f in load(session).files]
    assert files[0] == session and len(files) == 3
    assert {f.name: f for f in files}["base.yaml"] == tmp_path / "lab" / "base.yaml"
    assert {f.name: f for f in files}["upper_limb_21.yaml"].read_text() == SHIPPED.read_text()
    assert load(SHIPPED).files == (str(SHIPPED),)


def test_example_session_file():
    prot = load(SESSION_EXAMPLE)
    assert dict(prot.relabel) == {"RADIUS": "ULNA", "ULNA": "RADIUS"}
    assert prot.marker_names == load(SHIPPED).marker_names
    match = resolve_labels(prot, C3D_LABELS_STATIC)
    labels = C3D_LABELS_STATIC
    assert labels[match.columns["RADIUS"]] == "ULNA" and labels[match.columns["ULNA"]] == "RADIUS"
    assert labels[match.columns["MET5"]] == "MET5"


@pytest.mark.parametrize(
    "files, fragment, where",
    [
        ({"s.yaml": "schema_version: 1\nextends: nope.yaml\n"}, "extends: 'nope.yaml' not found", "s.yaml"),
        ({"s.yaml": "schema_version: 1\nextends: [a]\n"}, "extends must be the name of a protocol file", "s.yaml"),
        ({"s.yaml": "schema_version: 1\nextends: b.yaml\n", "b.yaml": "schema_version: 1\nextends: s.yaml\n"},
         "leads back to a file already in the chain", "b.yaml"),
        ({"s.yaml": "schema_version: 1\nextends: b.yaml\nrelabels: {A: B}\n", "b.yaml": MINIMAL},
         "unknown key 'relabels' (did you mean 'relabel'?)", "s.yaml"),
        ({"s.yaml": "schema_version: 1\nextends: b.yaml\n", "b.yaml": MINIMAL + "colour: red\n"},
         "unknown key 'colour'", "b.yaml"),
        ({"s.yaml": "extends: b.yaml\n", "b.yaml": MINIMAL}, "missing key 'schema_version'", "s.yaml"),
        ({"s.yaml": "schema_version: 1\nextends: b.yaml\n", "b.yaml": MINIMAL.replace("humerus", "humerous")},
         "markers.ARM.segment is 'humerous'", "b.yaml"),
        ({"s.yaml": "schema_version: 1\nextends: b.yaml\nrelabel: {A: A}\n", "b.yaml": MINIMAL},
         "relabel.A: reads 'A' as itself", "s.yaml"),
    ],
)
def test_extends_errors_name_the_file_and_key(tmp_path, files, fragment, where):
    for name, text in files.items():
        write(tmp_path, text, name=name)
    with pytest.raises(ProtocolError) as exc:
        load(tmp_path / "s.yaml")
    msg = str(exc.value)
    assert fragment in msg
    assert msg.startswith(str(tmp_path / where)), msg


def test_read_protocol_mapping_merges_the_extends_chain(tmp_path):
    from exubio.protocol.load import read_protocol_mapping

    data = read_protocol_mapping(SESSION_EXAMPLE)
    assert data["markers"]["RADIUS"] == {"segment": "radius", "point": "RADIUS", "landmark": "RS"}
    assert data["relabel"] == {"RADIUS": "ULNA", "ULNA": "RADIUS"} and "extends" not in data


def test_landmark_and_cluster_keys_are_read_and_checked(tmp_path):
    """landmark: names a model point of the marker's segment (checked against the model the
    protocol is used with); cluster: at least 3 markers of one segment; a marker is not both."""
    from exubio.protocol.load import check_landmarks

    base = MINIMAL.replace("  ARM: {segment: humerus, local_position_mm: [10, -200, 30]}\n", "")
    good = write(tmp_path, base + """\
      EPI_lat: {segment: humerus, point: EPI_lat, landmark: EPI_lat}
      SCAP_AC: {segment: scapula, point: SCAP_AC, cluster: acro}
      SCAP_BACK: {segment: scapula, point: SCAP_BACK, cluster: acro}
      SCAP_FRONT: {segment: scapula, point: SCAP_FRONT, cluster: acro}
    """)
    prot = load(good)
    by = {m.name: m for m in prot.markers}
    assert by["EPI_lat"].landmark == "EPI_lat" and by["EPI_lat"].cluster is None
    assert {by[n].cluster for n in ("SCAP_AC", "SCAP_BACK", "SCAP_FRONT")} == {"acro"}
    check_landmarks(prot, MODEL_POINTS)  # EPI_lat is a humerus point
    with pytest.raises(ProtocolError, match=r"EPI_lat.landmark 'EPI_lat' is not a point of segment 'humerus'"):
        check_landmarks(prot, {**MODEL_POINTS, "humerus": {"ARM": np.zeros(3)}})
    small = write(tmp_path, base + """\
      SCAP_AC: {segment: scapula, point: SCAP_AC, cluster: acro}
      SCAP_BACK: {segment: scapula, point: SCAP_BACK, cluster: acro}
    """, "small.yaml")
    with pytest.raises(ProtocolError, match=r"small.yaml: cluster 'acro' .* at least 3 markers"):
        load(small)
    both = write(tmp_path, base + """\
      EPI_lat: {segment: humerus, point: EPI_lat, landmark: EPI_lat, cluster: x}
    """, "both.yaml")
    with pytest.raises(ProtocolError, match=r"both a landmark and in cluster 'x'"):
        load(both)
