"""benchmarks/bench_peers.py hands the peers exubio's chain: the .osim and .bioMod it writes hold
exubio's 13 joint coordinates and nothing else (a free thorax, the .osim export's default since
2284b88, gave OpenSim's IK 19 coordinates and the script a shape error), and the protocol's markers
as their only markers. Read as XML and text here; loaded by opensim and biorbd where installed."""
from __future__ import annotations

import importlib.util
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def peer_files(tmp_path_factory):
    spec = importlib.util.spec_from_file_location("bench_peers", ROOT / "benchmarks" / "bench_peers.py")
    bp = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("bench_peers", bp)
    spec.loader.exec_module(bp)
    from exubio.run.inputs import load_model_and_protocol

    model, protocol = load_model_and_protocol()
    bio, osim = bp.write_peer_files(model, protocol, tmp_path_factory.mktemp("peers"))
    return model, protocol, bp.PREFIX, bio, osim


def test_the_osim_holds_exubios_coordinates_and_the_protocols_markers(peer_files):
    model, protocol, prefix, _, osim = peer_files
    root = ET.parse(osim).getroot()
    coords = [c.get("name") for c in root.iter("Coordinate")]
    assert coords == list(model.coordinate_names)
    welds = [j for j in root.iter("WeldJoint") if j.findtext("socket_parent_frame") == "/ground"]
    assert len(welds) == 1  # the thorax fixed to the ground, as exubio holds it
    markers = sorted(m.get("name") for m in root.iter("Marker"))
    assert markers == sorted(prefix + m.name for m in protocol.markers)


def test_the_biomod_holds_exubios_coordinates_and_the_protocols_markers(peer_files):
    model, protocol, prefix, bio, _ = peer_files
    text = bio.read_text()
    rot = re.findall(r"^\s*rotations\s+(\S+)", text, re.M)
    trans = re.findall(r"^\s*translations\s+(\S+)", text, re.M)
    assert sum(len(r) for r in rot) == model.n_coordinates and not trans
    markers = sorted(re.findall(r"^\s*marker\s+(\S+)", text, re.M))
    assert markers == sorted(prefix + m.name for m in protocol.markers)


def test_the_peers_load_the_same_chain(peer_files):
    model, _, _, bio, osim = peer_files
    opensim = pytest.importorskip("opensim")
    biorbd = pytest.importorskip("biorbd")
    o = opensim.Model(str(osim))
    o.initSystem()
    assert o.getCoordinateSet().getSize() == model.n_coordinates
    assert biorbd.Model(str(bio)).nbQ() == model.n_coordinates
