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

Read through a copy that ezc3d can read (``ezc3d_copy``), with a note: a file in the SGI/MIPS
processor format (byte 4 of the parameter section is 86: big-endian; ezc3d reads only Intel and
DEC files), turned into Intel byte order number by number (the header's words and floats, every
parameter's offset and its int16 or float values, every word of the data block), and a parameter
or group description longer than 127 characters (KINARM's Dexterit-E), whose length byte ezc3d
reads as negative: cut to 127 characters in the copy (exubio reads no description). Analog
channels ezc3d cannot read are left out of the copy (exubio reads marker trajectories): ANALOG:SCALE
or OFFSET with fewer values than channels (ezc3d crashes), or ANALOG:OFFSET stored as floats
(PhoeniX's samples; ezc3d refuses the file): that record is written as the integers the
standard wants, rounded, since ezc3d checks its type even with no channel left.

Refused, naming the field: a parameter block or data start past the end of the file,
a record of unknown type, more than 7 dimensions, type char with no dimension or data running into
the data block or past the file, an offset to the next record inside the record, a group id
defined twice, a parameter of no group, a name with control or non-ASCII characters, a POINT:USED,
SCALE, RATE, DATA_START or FRAMES (ANALOG:USED, RATE, GEN_SCALE; ROTATION:...) with no value, a
POINT:RATE that is not a finite number. ezc3d crashes on each of the last three (a segmentation
fault: it reads those parameters' first value or dimension unchecked; found by mutating the bytes
of parameter sections, studies/c3d_mutations.py). Also refused: a negative ROTATION:USED or RATIO,
by which ezc3d sizes its rotations block (a RATIO of -256 had it ask for 12 GB).
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
_COUNTS = {("ROTATION", "USED"), ("ROTATION", "RATIO")}  # ezc3d sizes the rotations block by them unchecked:
# a negative one asked for 12 GB (a mutated ROTATION:RATIO of -256, studies/c3d_mutations.py --seed 11)
_STANDARD_NAME = re.compile(r"^[A-Z0-9_]+$")
_BAD = "not a readable C3D file (the header contradicts the file: "
FLOAT_OFFSETS = ("ANALOG:OFFSET is stored as floating-point numbers, where the C3D standard and ezc3d, the C3D reader "
                 "exubio uses, want integers (ezc3d refuses the file)")


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
    needs_copy: bool = False  # ezc3d reads the file only through ``ezc3d_copy``
    analogs_unreadable: str = ""  # why ezc3d cannot read its analog channels: the copy leaves them out


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
    data_start = struct.unpack(byte_order + "H", header[16:18])[0]
    if data_start < 1 or (data_start - 1) * 512 >= size:
        raise InputError(f"{path}: {_BAD}its word 9 puts the data at 512-byte block {data_start}, byte "
                         f"{(max(data_start, 1) - 1) * 512}, but the file has {size} bytes)")
    notes: list[str] = []
    long: list[str] = []
    section, params = parameter_records(path, byte_order, param_block, size, notes=notes, long_descriptions=long)
    if processor == MIPS:
        notes.append(f"{path.name}: processor format SGI/MIPS (big-endian; byte 4 of the parameter section is {MIPS}), "
                     f"which ezc3d does not read: read through a copy in Intel byte order")
    analogs = _analogs_unreadable(section, params, byte_order)
    if analogs:
        notes.append(f"{path.name}: {analogs}: the markers are read without them")
    needs_copy = processor == MIPS or bool(long) or bool(analogs)
    _check_scales(path, header, section, params, processor)
    done = RawCheck(tuple(notes), None, needs_copy, analogs)
    if processor == DEC:
        return done  # VAX floats: ezc3d converts them; the rate is checked after reading
    point_rate = next((float(struct.unpack(byte_order + "f", section[p.start:p.start + 4])[0]) for p in params
                       if (p.group, p.name, p.kind) == ("POINT", "RATE", 4) and p.start + 4 <= len(section)), None)
    if point_rate is None or not rate_problem(point_rate):
        return done
    header_rate = float(struct.unpack(byte_order + "f", header[20:24])[0])
    if point_rate != point_rate or abs(point_rate) == float("inf") or rate_problem(header_rate):
        raise InputError(f"{path}: POINT:RATE is {rate_problem(point_rate)}; expected the marker sampling rate in Hz")
    notes.append(f"{path.name}: POINT:RATE is {rate_problem(point_rate)}; read at the header's rate (word 11-12), "
                 f"{header_rate:g} Hz")
    return RawCheck(tuple(notes), header_rate, needs_copy, analogs)


def _float(data: bytes, at: int, processor: int) -> float:
    """The 4-byte float at ``at``: IEEE little-endian (Intel), big-endian (MIPS), or VAX F-float
    (DEC: the two 16-bit words in the other order, and 4 times the IEEE value)."""
    if processor == DEC:
        return struct.unpack("<f", bytes(data[at + 2:at + 4]) + bytes(data[at:at + 2]))[0] / 4.0
    return struct.unpack((">" if processor == MIPS else "<") + "f", bytes(data[at:at + 4]))[0]


def _check_scales(path: Path, header: bytes, section: bytes, params: list[RawParameter], processor: int) -> None:
    """Refuse an integer-format file whose POINT:SCALE and header scale factor (words 7-8)
    disagree: every position is a stored integer times the scale, so the two would give positions
    that differ by their ratio, and the file cannot say which is right (ezc3d takes the parameter
    silently). In the float format the scale multiplies no coordinate, so a difference is harmless."""
    scale = next((_float(section, p.start, processor) for p in reversed(params)
                  if (p.group, p.name, p.kind) == ("POINT", "SCALE", 4) and p.start + 4 <= len(section)), None)
    if scale is None or not scale > 0:
        return
    in_header = _float(header, 12, processor)
    if abs(in_header) > 0 and abs(in_header - scale) > 1e-5 * abs(scale):
        raise InputError(
            f"{path}: its scale factors disagree: POINT:SCALE is {scale:.6g} and the header's (words 7-8) "
            f"{in_header:.6g}; its integer coordinates are multiplied by the scale, so the positions would differ "
            f"by a factor {max(scale, abs(in_header)) / min(scale, abs(in_header)):.3g} and the file cannot say "
            f"which is right; export the trial again (in the float format) from the software that recorded it")


def _analogs_unreadable(section: bytes, params: list[RawParameter], byte_order: str) -> str:
    """Why ezc3d cannot read the file's analog channels, or "": ANALOG:OFFSET stored as floats
    (ezc3d refuses the file: "OFFSET parameter is not an INT"), or ANALOG:USED > 0 with fewer
    ANALOG:SCALE or ANALOG:OFFSET values than channels (counted over SCALE, SCALE2, ... as ezc3d
    joins them). ezc3d takes one per channel unchecked: a segmentation fault, measured by removing
    either parameter from three vendors' files (an old Motion Analysis file names its offsets
    ANALOG:OFFSETS)."""
    last = {(p.group, p.name): p for p in params}
    if any(p.group == "ANALOG" and re.fullmatch(r"OFFSET\d*", p.name) and p.kind == 4 for p in params):
        return FLOAT_OFFSETS
    used = last.get(("ANALOG", "USED"))
    if used is None or used.kind != 2 or used.start + 2 > len(section):
        return ""
    n = struct.unpack(byte_order + "h", section[used.start:used.start + 2])[0]
    if n <= 0:
        return ""
    for name in ("SCALE", "OFFSET"):
        values, k, p = 0, 2, last.get(("ANALOG", name))
        absent = p is None
        while p is not None:
            values += int(np.prod(p.dims[1:] if p.kind == -1 else p.dims, dtype=np.int64)) if p.dims else 1
            p, k = last.get(("ANALOG", f"{name}{k}")), k + 1
        if values < n:
            return (f"ANALOG:USED is {n} but ANALOG:{name} "
                    f"{'is absent' if absent else f'holds {values} value(s)'}; expected one per channel; ezc3d "
                    f"cannot read such analog channels (it crashes)")
    return ""


def raw_parameters(path: Path, byte_order: str, param_block: int, size: int
                   ) -> tuple[bytes, list[tuple[str, str, int, int]]]:
    """The raw parameter section and its parameters as (group, name, type, offset of the data)."""
    section, params = parameter_records(path, byte_order, param_block, size)
    return section, [(p.group, p.name, p.kind, p.start) for p in params]


def parameter_records(path: Path, byte_order: str, param_block: int, size: int, *, notes: list[str] | None = None,
                      long_descriptions: list[str] | None = None) -> tuple[bytes, list[RawParameter]]:
    """The raw parameter section (from the parameter block to the data block, or to the end of the
    file) and its parameter records. A section that contradicts itself is refused: a parameter
    whose type is unknown or whose dimensions declare data running into the data block, a record
    whose offset to the next record lies inside it or past the section, a group id defined twice, a
    parameter of a group no record defines, a name that is no name (control or non-ASCII
    characters). ezc3d reads past its buffers on such sections (segmentation faults, measured: a
    255 x 255 POINT:LABELS, a parameter turned into a group by one byte). ``notes`` receives what is
    read around (a name outside the standard, records past the declared section length, a
    description longer than 127 characters); ``long_descriptions`` the records whose description
    is (ezc3d reads such a file only through ``ezc3d_copy``). Without ``long_descriptions`` such a
    section is refused."""
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
    long: list[str] = []
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
                long.append(f"{full} ({section[here + 2]} characters)")
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
                long.append(f"{full} ({section[start + n_bytes]} characters)")
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
    last = {(groups[g], name): (kind, dims, start) for g, name, kind, dims, start in raw}  # ezc3d keeps a repeated one's last
    for (group, name), (kind, dims, start) in last.items():
        if name in _INDEXED.get(group, ()) and int(np.prod(dims, dtype=np.int64)) == 0:
            refuse(f"parameter {group}:{name} holds no value (dimensions {list(dims)}); expected a number")
        if (group, name) in _COUNTS and kind == 2 and struct.unpack_from(byte_order + "h", section, start)[0] < 0:
            refuse(f"parameter {group}:{name} is {struct.unpack_from(byte_order + 'h', section, start)[0]}; expected a "
                   f"count of 0 or more (ezc3d would ask for gigabytes of memory for it)")
    counts = Counter(f"{groups[g]}:{name}" for g, name, *_ in raw)
    repeated = sorted(name for name, n in counts.items() if n > 1)
    if long and long_descriptions is None:
        raise InputError(
            f"{path}: not a readable C3D file (parameter section: the description of {long[0]}"
            f"{' and ' + str(len(long) - 1) + ' more' if len(long) > 1 else ''} is longer "
            f"than 127 characters; ezc3d, the C3D reader exubio uses, reads such a length byte as negative (it would "
            f"ask for 4 GB) and cannot read the file; shorten the description in the software that wrote it)")
    if long_descriptions is not None:
        long_descriptions += long
    if notes is not None:
        if long:
            notes.append(f"{path.name}: parameter section: the description of {', '.join(long)} is longer than the "
                         f"127 characters ezc3d reads; read with it cut to 127 (exubio reads no description)")
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


# --------------------------------------------------------------------------------------------
# A copy ezc3d can read
# --------------------------------------------------------------------------------------------
_HEADER_FLOATS = ((12, 16), (20, 24), (304, 376))  # byte ranges of the header's floats: scale, rate, 18 event times
_HEADER_BYTES = ((0, 2), (376, 394), (396, 468))  # bytes, not words: parameter block and key, event flags and labels


def ezc3d_copy(path: Path, *, drop_analogs: bool = False) -> bytes:
    """The file's bytes as ezc3d reads them (see the module docstring): a SGI/MIPS (big-endian) file
    in Intel byte order, number by number, with byte 4 of its parameter section set to 84; every
    description longer than 127 characters cut to 127 (its length byte; the record's offset to the
    next record, which readers follow, is kept); with ``drop_analogs`` (``RawCheck.analogs_unreadable``)
    without its analog channels (ANALOG:USED and the header's analog counts 0, each frame of the
    data block its point words only, ANALOG:OFFSET stored as floats written as int16, rounded).
    Call it on a file ``check_raw_header`` has accepted: the records are walked as it checked them."""
    data = bytearray(path.read_bytes())
    first = (data[0] - 1) * 512
    processor = data[first + 3]
    swap = processor == MIPS
    order = ">" if swap else "<"
    negative_header = _float(data, 12, processor) < 0  # the header's scale (words 7-8)
    if swap:
        _swap_header(data)
        data[first + 3] = INTEL
    negative = None  # POINT:SCALE < 0: the data block holds floats
    records: list[tuple[int, int, int, int]] = []  # start, its offset word, its description's length byte, step
    retyped: dict[int, bytes] = {}  # record index -> its type, dimensions and values as the copy writes them
    pos = first + 4
    groups: dict[int, str] = {}
    while pos + 2 <= len(data):
        n_chars, ident = struct.unpack_from("bb", data, pos)
        if n_chars == 0:
            break
        name = data[pos + 2:pos + 2 + abs(n_chars)].decode("latin-1").upper()
        here = pos + 2 + abs(n_chars)
        step = struct.unpack_from(order + "h", data, here)[0]
        if swap:
            _swap_words(data, here, here + 2, 2)
        if ident < 0:
            groups[-ident] = name
            describe = here + 2
        else:
            kind, n_dims = struct.unpack_from("bB", data, here + 2)
            start = here + 4 + n_dims
            count = int(np.prod(tuple(data[here + 4:start]), dtype=np.int64))
            end = start + _TYPE_BYTES[kind] * count
            if (groups.get(ident), name, kind) == ("POINT", "SCALE", 4) and count:
                negative = _float(data, start, processor) < 0
            if swap and kind in (2, 4):
                _swap_words(data, start, end, kind)
            if drop_analogs and (groups.get(ident), name, kind) == ("ANALOG", "USED", 2) and count:
                struct.pack_into("<h", data, start, 0)
            if drop_analogs and groups.get(ident) == "ANALOG" and re.fullmatch(r"OFFSET\d*", name) and kind == 4:
                values = [_float(data, start + 4 * i, INTEL if swap else processor) for i in range(count)]
                ints = np.clip(np.rint(np.nan_to_num(values)), -32768, 32767).astype("<i2").tobytes()
                retyped[len(records)] = struct.pack("b", 2) + bytes(data[here + 3:start]) + ints
            describe = end
        records.append((pos, here, describe, step))
        if step <= 0:
            break
        pos = here + step
    if retyped or any(data[d] > 127 for _, _, d, _ in records):
        _rewrite_records(data, records, retyped)
    data_start = (struct.unpack_from("<H", data, 16)[0] - 1) * 512  # the header is in Intel order by now
    # float format when POINT:SCALE (else the header's scale) < 0, else int16: points and analogs alike
    word = 4 if (negative if negative is not None else negative_header) else 2
    if swap:
        _swap_words(data, data_start, data_start + (len(data) - data_start) // word * word, word)
    if drop_analogs:
        n_points, n_analog = struct.unpack_from("<2H", data, 2)
        frame = 4 * n_points + n_analog  # words per frame
        n_frames = (len(data) - data_start) // (frame * word)
        block = np.frombuffer(data, dtype=np.uint8, count=n_frames * frame * word, offset=data_start)
        points = block.reshape(n_frames, frame * word)[:, : 4 * n_points * word].tobytes()
        del block  # a view of data: gone before data is resized
        struct.pack_into("<H", data, 4, 0)  # word 3: analog samples per frame, all channels
        struct.pack_into("<H", data, 18, 0)  # word 10: analog samples per frame and channel
        data[data_start:] = points
    return bytes(data)


def _rewrite_records(data: bytearray, records: list[tuple[int, int, int, int]], retyped: dict[int, bytes]) -> None:
    """Every description longer than 127 characters cut to its first 127 and the records of
    ``retyped`` (index -> type, dimensions and values) rewritten, the records after them moved up and
    their offsets to the next record made to match (ezc3d requires each record to end where the
    previous one's offset points), zeros where the section got shorter."""
    chunks = []
    for i, (pos, here, describe, step) in enumerate(records):
        n = min(data[describe], 127)
        body = retyped[i] if i in retyped else data[here + 2:describe]
        chunk = bytearray(data[pos:here + 2]) + body + bytes([n]) + data[describe + 1:describe + 1 + n]
        if step > 0:
            struct.pack_into("<h", chunk, here - pos, len(chunk) - (here - pos))  # Intel order: the copy's
        chunks.append(bytes(chunk))
    first, last = records[0][0], records[-1][2] + 1 + data[records[-1][2]]
    joined = b"".join(chunks)
    data[first:last] = joined + bytes(last - first - len(joined))


def _swap_header(data: bytearray) -> None:
    """The 512-byte header from big- to little-endian: int16 words, its floats as 4-byte words, its
    byte fields as they are."""
    keep = {i for a, b in _HEADER_BYTES for i in range(a, b)}
    floats = {i for a, b in _HEADER_FLOATS for i in range(a, b)}
    for a, b in _HEADER_FLOATS:
        _swap_words(data, a, b, 4)
    for i in range(0, 512, 2):
        if i not in keep and i not in floats:
            data[i], data[i + 1] = data[i + 1], data[i]


def _swap_words(data: bytearray, start: int, end: int, size: int) -> None:
    """Reverse the bytes of each ``size``-byte word in data[start:end], in place."""
    words = np.frombuffer(data, dtype=np.uint8, count=end - start, offset=start).reshape(-1, size)
    data[start:end] = words[:, ::-1].tobytes()
