"""The raw bytes of a C3D file, looked at before ezc3d reads it (exubio.io.c3d): the 512-byte
header and the parameter section. ezc3d crashes or allocates what the file asks on a header or a
parameter section that contradicts itself, so those are refused here naming the field; what
vendors write outside the standard but ezc3d reads is read, with a note naming it (an input
finding, ``Trajectories.input_findings``).

Read around, with a note:
- a parameter or group named with characters the standard does not allow in a name (Qualisys QTM:
  "Uncropped Measurement Length", BTS: "PELVIS WIDTH"): ezc3d reads names by their length;
- parameters running past the section length that byte 3 of the parameter section declares (Peak
  Performance, PhoeniX): ezc3d reads the records where they are, to the terminating record;
- a parameter defined twice in its group: the last definition, as ezc3d reads it;
- a POINT:RATE of 0, negative or above exubio.io.limits.MAX_RATE_HZ under a usable header rate
  (word 11-12): the header's rate is used.

Refused, naming the field: the SGI/MIPS processor format (byte 4 of the parameter section is 86;
ezc3d reads only Intel and DEC files), a parameter block or data start past the end of the file,
a record of unknown type, more than 7 dimensions, type char with no dimension or data running into
the data block or past the file, an offset to the next record inside the record, a group id
defined twice, a parameter of no group, a name with control or non-ASCII characters, a POINT:USED,
SCALE, RATE, DATA_START or FRAMES (ANALOG:USED, RATE, GEN_SCALE; ROTATION:...) with no value, a
POINT:RATE that is not a finite number. ezc3d crashes on each of the last three (a segmentation
fault: it reads those parameters' first value or dimension unchecked; found by mutating the bytes
of parameter sections, studies/c3d_mutations.py).
"""
from __future__ import annotations

import re
import struct
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from exubio.errors import InputError
from exubio.io.limits import rate_problem

HEADER_CLIPPED = 0xFFFF  # a 16-bit header frame number: long trials store the real count elsewhere
INTEL, DEC, MIPS = 84, 85, 86  # processor type byte of the parameter section
_TYPE_BYTES = {-1: 1, 1: 1, 2: 2, 4: 4}  # C3D parameter types: char, byte, int16, float
_INDEXED = {"POINT": ("USED", "SCALE", "RATE", "DATA_START", "FRAMES"), "ANALOG": ("USED", "RATE", "GEN_SCALE"),
            "ROTATION": ("USED", "RATE", "RATIO", "DATA_START")}  # ezc3d reads their first value unchecked
MAX_SECTION_BLOCKS = 2048  # 1 MB: what is read of a parameter section whatever its header says (255 blocks declarable)
_STANDARD_NAME = re.compile(r"^[A-Z0-9_]+$")
_BAD = "not a readable C3D file (the header contradicts the file: "


@dataclass(frozen=True)
class RawParameter:
    """A parameter record of the raw section: its group and name, type, dimensions and the offset
    of its data in the section."""

    group: str
    name: str
    kind: int
    dims: tuple[int, ...]
    start: int


@dataclass(frozen=True)
class RawCheck:
    """What the raw check read around (notes, one sentence each naming the field) and the rate to
    use when POINT:RATE is unusable but the header's is (None: the rate ezc3d reads)."""

    notes: tuple[str, ...] = ()
    rate_hz: float | None = None


def raw_header(path: Path) -> tuple[str, int, bytes]:
    """(struct byte order, processor type byte, the raw 512-byte header) of a C3D file."""
    with open(path, "rb") as fh:
        header = fh.read(512)
        fh.seek(max(header[0] - 1, 0) * 512 + 3 if header else 0)
        processor = fh.read(1)
    kind = processor[0] if processor else 0
    return (">" if kind == MIPS else "<"), kind, header  # MIPS big-endian; Intel, DEC little


def check_raw_header(path: Path) -> RawCheck:
    """Refuse, before ezc3d reads it, a file whose header points past its end, whose processor
    format ezc3d cannot read, whose parameter section contradicts itself or whose POINT:RATE is not
    a finite number; return what was read around (see the module docstring). ezc3d itself gives an
    error for a header shorter than 512 bytes."""
    if not path.is_file():
        return RawCheck()  # exubio.io.c3d._open says why
    size = path.stat().st_size
    byte_order, processor, header = raw_header(path)
    if len(header) < 512:
        return RawCheck()
    param_block = header[0]
    if param_block < 1 or (param_block - 1) * 512 + 4 > size:
        raise InputError(f"{path}: {_BAD}its first byte puts the parameter block at 512-byte block {param_block}, "
                         f"byte {(max(param_block, 1) - 1) * 512}, but the file has {size} bytes)")
    if processor == MIPS:
        raise InputError(
            f"{path}: processor format SGI/MIPS (big-endian; byte 4 of the parameter section is {MIPS}) is not "
            f"supported: ezc3d, the C3D reader exubio uses, reads the Intel (PC, {INTEL}) and DEC ({DEC}) formats; "
            f"export the trial again in the Intel (PC) format")
    data_start = struct.unpack(byte_order + "H", header[16:18])[0]
    if data_start < 1 or (data_start - 1) * 512 >= size:
        raise InputError(f"{path}: {_BAD}its word 9 puts the data at 512-byte block {data_start}, byte "
                         f"{(max(data_start, 1) - 1) * 512}, but the file has {size} bytes)")
    notes: list[str] = []
    section, params = parameter_records(path, byte_order, param_block, size, notes=notes)
    if processor == DEC:
        return RawCheck(tuple(notes))  # VAX floats: ezc3d converts them; the rate is checked after reading
    point_rate = next((float(struct.unpack(byte_order + "f", section[p.start:p.start + 4])[0]) for p in params
                       if (p.group, p.name, p.kind) == ("POINT", "RATE", 4) and p.start + 4 <= len(section)), None)
    if point_rate is None or not rate_problem(point_rate):
        return RawCheck(tuple(notes))
    header_rate = float(struct.unpack(byte_order + "f", header[20:24])[0])
    if point_rate != point_rate or abs(point_rate) == float("inf") or rate_problem(header_rate):
        raise InputError(f"{path}: POINT:RATE is {rate_problem(point_rate)}; expected the marker sampling rate in Hz")
    notes.append(f"{path.name}: POINT:RATE is {rate_problem(point_rate)}; read at the header's rate (word 11-12), "
                 f"{header_rate:g} Hz")
    return RawCheck(tuple(notes), header_rate)


def raw_parameters(path: Path, byte_order: str, param_block: int, size: int
                   ) -> tuple[bytes, list[tuple[str, str, int, int]]]:
    """The raw parameter section and its parameters as (group, name, type, offset of the data)."""
    section, params = parameter_records(path, byte_order, param_block, size)
    return section, [(p.group, p.name, p.kind, p.start) for p in params]


def parameter_records(path: Path, byte_order: str, param_block: int, size: int, *, notes: list[str] | None = None
                      ) -> tuple[bytes, list[RawParameter]]:
    """The raw parameter section (from the parameter block to the data block, or to the end of the
    file) and its parameter records. A section that contradicts itself is refused: a parameter
    whose type is unknown or whose dimensions declare data running into the data block, a record
    whose offset to the next record lies inside it or past the section, a group id defined twice, a
    parameter of a group no record defines, a name that is no name (control or non-ASCII
    characters). ezc3d reads past its buffers on such sections (segmentation faults, measured: a
    255 x 255 POINT:LABELS, a parameter turned into a group by one byte). ``notes`` receives what is
    read around (a name outside the standard, records past the declared section length)."""
    header = raw_header(path)[2]
    data_start = struct.unpack(byte_order + "H", header[16:18])[0] if len(header) >= 18 else 0
    first = (param_block - 1) * 512
    declared_end = first + (section_blocks(path, first) or 1) * 512
    end_of_section = max((data_start - 1) * 512, declared_end) if data_start > param_block else size
    end_of_section = min(end_of_section, first + MAX_SECTION_BLOCKS * 512)
    with open(path, "rb") as fh:
        fh.seek(first)
        section = fh.read(max(min(end_of_section, size) - first, 0))
    if len(section) < 4:
        return section, []
    declared = section[2] * 512
    groups: dict[int, str] = {}
    raw: list[tuple[int, str, int, tuple[int, ...], int]] = []  # group id, name, type, dims, data start
    odd_names: list[str] = []
    long_descriptions: list[str] = []
    where = "the data block" if data_start > param_block else "the file"
    reached = 0

    def refuse(what: str) -> None:
        raise InputError(f"{path}: {_BAD}parameter section: {what})")

    pos = 4
    while pos + 2 <= len(section):
        n_chars, ident = struct.unpack("bb", section[pos:pos + 2])
        if n_chars == 0:
            break
        name = section[pos + 2:pos + 2 + abs(n_chars)].decode("latin-1").upper()
        here = pos + 2 + abs(n_chars)
        if here + 3 > len(section):
            break
        if ident == 0 or not name.isprintable() or not name.isascii() or not name.strip():
            refuse(f"a record at byte {pos} is named {name!r} in group 0 or with characters that are not a name")
        step = struct.unpack(byte_order + "h", section[here:here + 2])[0]
        if ident < 0:
            if -ident in groups:
                refuse(f"group id {-ident} is defined twice ({groups[-ident]} and {name})")
            groups[-ident] = name
            full = name
            end = here + 3 + section[here + 2]  # its description
            if section[here + 2] > 127:
                long_descriptions.append(f"{full} ({section[here + 2]} characters)")
        else:
            kind, n_dims = struct.unpack("bB", section[here + 2:here + 4])
            dims = tuple(section[here + 4:here + 4 + n_dims])
            full = f"{groups.get(ident, f'group {ident}')}:{name}"
            if kind not in _TYPE_BYTES or n_dims > 7:
                refuse(f"parameter {full} has type {kind} and {n_dims} dimensions; expected a type of -1, 1, 2 or 4 "
                       f"and at most 7")
            if kind == -1 and n_dims == 0:  # ezc3d indexes its first dimension: a segmentation fault (fuzzed)
                refuse(f"parameter {full} is of type char with no dimension; expected at least one (its length)")
            start = here + 4 + n_dims
            n_bytes = _TYPE_BYTES[kind] * int(np.prod(dims, dtype=np.int64))
            if start + n_bytes + 1 > len(section):
                refuse(f"parameter {full} declares dimensions {list(dims)}, {n_bytes} bytes, past the end of the "
                       f"{len(section)}-byte section (it ends where {where} starts)")
            end = start + n_bytes + 1 + section[start + n_bytes]  # its description
            if section[start + n_bytes] > 127:
                long_descriptions.append(f"{full} ({section[start + n_bytes]} characters)")
            raw.append((ident, name, kind, dims, start))
        if end > len(section) or (step > 0 and here + step < end) or here + step > len(section):
            refuse(f"the record {full} at byte {pos} ends at byte {end} but its offset to the next record is {step} "
                   f"(from byte {here}) in a {len(section)}-byte section")
        if not _STANDARD_NAME.match(name):
            odd_names.append(full)
        reached = max(reached, end)
        if step <= 0:
            break
        pos = here + step
    for ident, name, _, _, _ in raw:
        if ident not in groups:
            refuse(f"parameter {name} belongs to group {ident}, which no group record defines")
    last = {(groups[g], name): dims for g, name, _, dims, _ in raw}  # ezc3d keeps a repeated one's last
    for (group, name), dims in last.items():
        if name in _INDEXED.get(group, ()) and int(np.prod(dims, dtype=np.int64)) == 0:
            refuse(f"parameter {group}:{name} holds no value (dimensions {list(dims)}); expected a number")
    counts = Counter(f"{groups[g]}:{name}" for g, name, *_ in raw)
    repeated = sorted(name for name, n in counts.items() if n > 1)
    if long_descriptions:
        raise InputError(
            f"{path}: not a readable C3D file (parameter section: the description of {long_descriptions[0]}"
            f"{' and ' + str(len(long_descriptions) - 1) + ' more' if len(long_descriptions) > 1 else ''} is longer "
            f"than 127 characters; ezc3d, the C3D reader exubio uses, reads such a length byte as negative (it would "
            f"ask for 4 GB) and cannot read the file; shorten the description in the software that wrote it)")
    if notes is not None:
        if odd_names:
            notes.append(f"{path.name}: parameter section: {len(odd_names)} name(s) outside the C3D naming rule "
                         f"(letters, digits and '_'): {', '.join(repr(n) for n in odd_names)}; read as written")
        if repeated:
            notes.append(f"{path.name}: parameter section: {', '.join(repeated)} defined twice or more; read the "
                         f"last definition, as ezc3d does")
        if reached > declared:
            notes.append(f"{path.name}: parameter section: byte 3 of its first block declares {section[2]} block(s) "
                         f"({declared} bytes) but its records run to byte {reached}; read them where they are, as "
                         f"ezc3d does")
    return section, [RawParameter(groups[g], name, kind, dims, start) for g, name, kind, dims, start in raw]


def section_blocks(path: Path, first: int) -> int:
    """Byte 3 of the parameter section (at byte ``first``): its length in 512-byte blocks."""
    with open(path, "rb") as fh:
        fh.seek(first + 2)
        byte = fh.read(1)
    return byte[0] if byte else 0


def header_count_findings(path: Path, n_read: int) -> list[str]:
    """Warnings for a header frame count the data block contradicts, read as the data hold: a last
    frame before the first; a last frame of 65535 over fewer frames and no count elsewhere."""
    byte_order, _, header = raw_header(path)
    if len(header) < 10:
        return []
    first, last = struct.unpack(byte_order + "2H", header[6:10])
    if last < first:
        return [f"{path.name}: the header's last frame (word 5) is {last}, before its first frame (word 4) "
                f"{first}; read the {n_read} frames the data block holds"]
    if last == HEADER_CLIPPED and n_read < last - first + 1:
        return [f"{path.name}: the header's last frame (word 5) is 65535 (more frames than 16 bits count, "
                f"see POINT:LONG_FRAMES) but there is no POINT:LONG_FRAMES and the data block holds "
                f"{n_read} frames; read those {n_read}"]
    return []


def declared_frame_count(path: Path) -> int | None:
    """Frames declared by the raw header (last - first + 1), None when it cannot say."""
    byte_order, _, header = raw_header(path)
    if len(header) < 10:
        return None
    first, last = struct.unpack(byte_order + "2H", header[6:10])
    if last == HEADER_CLIPPED or last < first:
        return None
    return last - first + 1


def declared_point_count(path: Path) -> int | None:
    """3-D points declared by the raw header (word 2), None when it cannot say."""
    byte_order, _, header = raw_header(path)
    return struct.unpack(byte_order + "H", header[2:4])[0] if len(header) >= 4 else None
