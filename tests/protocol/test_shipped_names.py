"""Shipped protocols and models are found by name from any folder (`--protocol upper_limb_21`),
listed by `exubio protocols`, and `exubio model-points` prints the points a protocol can name in the
segment frames `local_position_mm` uses."""
import numpy as np

from exubio.cli import main
from exubio.model.load import load_model
from exubio.protocol.load import resolve_protocol, shipped_protocols
from exubio.io.resources import shipped_file


def test_names_resolve_to_the_shipped_files_from_any_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # no protocols/ or models/ folder here
    assert resolve_protocol("upper_limb_21") == shipped_file("exubio.protocols", "upper_limb_21.yaml", "protocols")
    assert resolve_protocol("thoracoscapular_9.yaml").is_file()
    assert load_model("upper_extremity").name == load_model().name
    assert set(shipped_protocols()) >= {"upper_limb_21", "thoracoscapular_9"}
    example = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
    assert main(["-q", "reconstruct", str(example), "--protocol", "upper_limb_21", "--model", "upper_extremity",
                 "--method", "ls", "--no-report", "--out", "out"]) == 0
    assert (tmp_path / "out" / "example_abduction.ls.csv").is_file()
    assert main(["-q", "reconstruct", str(example), "--protocol", "no_such_protocol", "--out", "o2"]) == 2
    assert "no_such_protocol" in capsys.readouterr().err


def test_the_protocols_command_lists_them_and_their_markers(capsys):
    assert main(["protocols"]) == 0
    out = capsys.readouterr().out
    assert "upper_limb_21" in out and "thoracoscapular_9" in out
    assert main(["protocols", "upper_limb_21"]) == 0
    out = capsys.readouterr().out
    assert "EPI_lat" in out and "landmark EL" in out and "thorax frame from ij=MAN" in out


def test_model_points_are_printed_in_the_segment_frame(capsys):
    assert main(["model-points", "--segment", "humerus"]) == 0
    out = capsys.readouterr().out
    model = load_model()
    local = model.segment("humerus").points["EPI_lat"] * 1000
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("EPI_lat"))
    values = np.array([float(x) for x in line.split("[")[1].rstrip("]").split(",")])
    np.testing.assert_allclose(values, local, atol=0.05)  # the numbers local_position_mm would take
    assert main(["model-points", "--segment", "nose"]) == 2
