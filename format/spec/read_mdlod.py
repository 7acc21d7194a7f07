#!/usr/bin/env python3
"""An independent reader of the `.mdlod` file format, written from FORMAT.md alone.

This is the executable companion of the specification (FORMAT.md at the repository
root). It was written from that text without looking at the Rust reader in
`format/src/`, to show that the text is enough to implement the format in another
language; `tests/format_spec.rs` checks that it decodes exactly what the Rust reader
decodes and refuses what it refuses. Where the two disagree, FORMAT.md is wrong or
incomplete: the text is fixed (the Rust code decides what files contain) and this
reader follows the fixed text.

It reads the whole file into memory (a real reader would memory-map it), performs the
validation of FORMAT.md section 8 including everything the full check (`mdlod verify`)
adds, and decodes every point of every level. The code follows the sections of
FORMAT.md in order; the section numbers in the comments are those of FORMAT.md.

Usage:

    python3 format/spec/read_mdlod.py FILE [--dump OUT.json]

Without `--dump` it prints a one-line summary. With it, it writes a JSON object with the
header, the section table, the metadata, the levels table, the node records and the
decoded points of every level (positions as the `repr` of their single-precision
values, so they compare exactly; on the particle level also the species and the
attribute). A file that breaks the format is reported on stderr as
`FILE: PLACE: PROBLEM` with exit status 1.

Needs Python 3 and the `xxhash` module (Debian: python3-xxhash; `bash scripts/setup.sh`
installs it).
"""

import argparse
import json
import math
import struct
import sys

try:
    import xxhash
except ImportError:  # pragma: no cover - environment problem, not a file problem
    sys.stderr.write(
        "read_mdlod.py needs the Python module xxhash (Debian package python3-xxhash): "
        "run `bash scripts/setup.sh`\n"
    )
    sys.exit(2)


def xxh3_64(data):
    """XXH3-64 with seed 0 and the default secret (FORMAT.md, introduction)."""
    return xxhash.xxh3_64_intdigest(data)


class FormatError(Exception):
    """A violation of the format, reported as `FILE: PLACE: PROBLEM`."""

    def __init__(self, place, problem):
        super().__init__(f"{place}: {problem}")


# ---------------------------------------------------------------------------------------
# Single-precision arithmetic. Python floats are binary64; every f32 value is exactly a
# binary64 value, and the exact result of one +, -, * or / of two f32 values rounded once to
# binary64 and then to binary32 equals the correctly rounded binary32 result. So each
# f32 operation below is "compute in binary64, round with f32()".

_F32 = struct.Struct("<f")


def f32(x):
    """`x` rounded to the nearest binary32 value (ties to even), overflow to ±inf."""
    try:
        return _F32.unpack(_F32.pack(x))[0]
    except OverflowError:
        return math.copysign(math.inf, x)


# ---------------------------------------------------------------------------------------
# Section 2: the header.

MAGIC = b"\x89MDLOD\r\n"
HEADER_SIZE = 64
# The range of major versions this reader reads (section 2, "Versions").
MAJOR_MIN, MAJOR_MAX = 1, 1
HEADER = struct.Struct("<8sHHIIIQQQQQ")
HEADER_FIELDS = (
    "magic",
    "version_major",
    "version_minor",
    "flags",
    "section_count",
    "position_bits",
    "section_table_offset",
    "file_size",
    "section_table_checksum",
    "reserved",
    "header_checksum",
)
assert HEADER.size == HEADER_SIZE

# Section 3: the section table.
SECTION = struct.Struct("<IIQQQ")
SECTION_FIELDS = ("kind", "level", "offset", "length", "checksum")
assert SECTION.size == 32

(
    METADATA,
    LEVELS,
    NODES,
    POSITIONS,
    SPECIES,
    ATTRIBUTE,
    RADIUS,
    RADIUS_LOG,
    ATTRIBUTES,
    NODE_ATTRIBUTES,
) = range(1, 11)
KIND_NAMES = {
    METADATA: "METADATA",
    LEVELS: "LEVELS",
    NODES: "NODES",
    POSITIONS: "POSITIONS",
    SPECIES: "SPECIES",
    ATTRIBUTE: "ATTRIBUTE",
    RADIUS: "RADIUS",
    RADIUS_LOG: "RADIUS_LOG",
    ATTRIBUTES: "ATTRIBUTES",
    NODE_ATTRIBUTES: "NODE_ATTRIBUTES",
}
PER_LEVEL_KINDS = (POSITIONS, SPECIES, ATTRIBUTE, RADIUS, RADIUS_LOG, ATTRIBUTES)
MAX_EXTRA_ATTRIBUTES = 64
METADATA_MAX = 16 << 20
MAX_SECTIONS = 1 << 16

# Section 4: the levels table.
LEVEL = struct.Struct("<QQQQ")
assert LEVEL.size == 32
MAX_LEVELS = 255
U32_MAX = 2**32 - 1

# Section 5: node records.
NODE = struct.Struct("<3ff3ff3ff3f7IfBBH")
assert NODE.size == 96
NO_NODE = 0xFFFFFFFF


# Section 7: the METADATA fields and their types. A type is "string", "number" (an f64;
# "f32" where it is read as single precision), "bool", an integer range name, "TYPE[n]"
# (an array of exactly n of them), "TYPE[]" (an array of any length), or a dict (a
# nested object). Each field is REQUIRED, OPTIONAL (absent or null) or DEFAULT (absent,
# but not null). Unknown fields are ignored; a known field may not appear twice.
REQUIRED, OPTIONAL, DEFAULT = "required", "optional", "default"
INTEGERS = {
    "u32": (0, 2**32 - 1),
    "u64": (0, 2**64 - 1),
    "i64": (-(2**63), 2**63 - 1),
}
SPECIES_FIELDS = {
    "name": ("string", REQUIRED),
    "radius": ("f32", REQUIRED),
    "colour": ("f32[3]", REQUIRED),
    "radius_range": ("f32[2]", OPTIONAL),
}
METADATA_FIELDS = {
    "particles": ("u64", REQUIRED),
    "box": (
        {
            "origin": ("number[3]", REQUIRED),
            "a": ("number[3]", REQUIRED),
            "b": ("number[3]", REQUIRED),
            "c": ("number[3]", REQUIRED),
            "periodic": ("bool[3]", OPTIONAL),
        },
        OPTIONAL,
    ),
    "timestep": ("u64", OPTIONAL),
    "time": ("number", OPTIONAL),
    "units": ("string", OPTIONAL),
    "species_column": ("string", OPTIONAL),
    "species": ((SPECIES_FIELDS, "[]"), REQUIRED),
    "attribute": (
        {"name": ("string", REQUIRED), "min": ("f32", REQUIRED), "max": ("f32", REQUIRED)},
        OPTIONAL,
    ),
    # Version 1.2: further attributes (ATTRIBUTES and NODE_ATTRIBUTES).
    "attributes": (
        (
            {"name": ("string", REQUIRED), "min": ("f32", REQUIRED), "max": ("f32", REQUIRED)},
            "[]",
        ),
        OPTIONAL,
    ),
    # Version 1.1: the range of the RADIUS section's radii.
    "radius": ({"min": ("f32", REQUIRED), "max": ("f32", REQUIRED)}, OPTIONAL),
    # Version 1.2: the range of the RADIUS_LOG section's radii (a log scale).
    "radius_log": ({"min": ("f32", REQUIRED), "max": ("f32", REQUIRED)}, OPTIONAL),
    "source": (
        {
            "path": ("string", REQUIRED),
            "size": ("u64", REQUIRED),
            "modified_unix": ("i64", OPTIONAL),
            "modified_nanos": ("u32", OPTIONAL),
            "frame": ("u64", OPTIONAL),
            "bytes": (
                {
                    "start": ("u64", REQUIRED),
                    "end": ("u64", REQUIRED),
                    "xxh3": ("string", REQUIRED),
                },
                OPTIONAL,
            ),
        },
        OPTIONAL,
    ),
    "build": (
        {
            "max_cluster_size": ("u32", REQUIRED),
            "max_root_points": ("u32", REQUIRED),
            "delta_n": ("u32", REQUIRED),
            "position_bits": ("u32", REQUIRED),
            "chunk_points": ("u64", OPTIONAL),
        },
        REQUIRED,
    ),
    "max_position_error": ("number", REQUIRED),
    "writer": ("string", REQUIRED),
}


class JsonObject(dict):
    """A JSON object that remembers the keys it had twice."""

    def __init__(self, pairs):
        super().__init__()
        self.twice = set()
        for key, value in pairs:
            if key in self:
                self.twice.add(key)
            self[key] = value


def check_value(value, kind, where):
    """Checks one JSON value against a type of METADATA_FIELDS."""
    if isinstance(kind, dict):
        if not isinstance(value, dict):
            raise FormatError("METADATA", f"{where} is not an object")
        check_fields(value, kind, where + ".")
        return
    if isinstance(kind, tuple):  # (element type, "[]")
        kind = kind[0]
        if not isinstance(value, list):
            raise FormatError("METADATA", f"{where} is not an array")
        for i, v in enumerate(value):
            check_value(v, kind, f"{where}[{i}]")
        return
    if kind.endswith("]"):
        element, n = kind[:-1].split("[")
        if not isinstance(value, list) or len(value) != int(n):
            raise FormatError("METADATA", f"{where} is not an array of {n} values")
        for i, v in enumerate(value):
            check_value(v, element, f"{where}[{i}]")
        return
    if kind == "string":
        ok = isinstance(value, str)
    elif kind == "bool":
        ok = isinstance(value, bool)
    elif kind in ("number", "f32"):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    else:
        lo, hi = INTEGERS[kind]
        ok = isinstance(value, int) and not isinstance(value, bool) and lo <= value <= hi
    if not ok:
        raise FormatError("METADATA", f"{where} is {json.dumps(value)}, not a {kind}")


def check_fields(obj, fields, prefix):
    for key, (kind, presence) in fields.items():
        where = prefix + key
        if key in obj.twice:
            raise FormatError("METADATA", f"{where} appears twice")
        if key not in obj:
            if presence == REQUIRED:
                raise FormatError("METADATA", f"{where} is missing")
            continue
        if obj[key] is None and presence == OPTIONAL:
            continue
        check_value(obj[key], kind, where)


class Node:
    """One 96-byte node record (section 5)."""

    __slots__ = (
        "centroid",
        "radius",
        "quant_scale",
        "area_sum",
        "bounds_min",
        "attribute",
        "bounds_max",
        "colour",
        "child_first",
        "child_count",
        "point_first",
        "point_count",
        "parent",
        "quant_node",
        "rms_radius",
        "level",
        "point_level",
        "species",
    )

    def __init__(self, raw):
        v = NODE.unpack(raw)
        self.centroid = v[0:3]
        self.radius = v[3]
        self.quant_scale = v[4:7]
        self.area_sum = v[7]
        self.bounds_min = v[8:11]
        self.attribute = v[11]
        self.bounds_max = v[12:15]
        (
            self.colour,
            self.child_first,
            self.child_count,
            self.point_first,
            self.point_count,
            self.parent,
            self.quant_node,
            self.rms_radius,
            self.level,
            self.point_level,
            self.species,
        ) = v[15:]

    def floats(self):
        return (
            self.centroid
            + (self.radius,)
            + self.quant_scale
            + (self.area_sum,)
            + self.bounds_min
            + (self.attribute,)
            + self.bounds_max
            + (self.rms_radius,)
        )

    def to_json(self):
        return {name: getattr(self, name) for name in self.__slots__}


class MdlodFile:
    """A `.mdlod` file, checked as FORMAT.md section 8's full check does and decoded
    (every point of every level) on construction; raises FormatError."""

    def __init__(self, path):
        self.path = path
        with open(path, "rb") as f:
            self.data = f.read()
        self.check_header()
        self.check_section_table()
        self.check_metadata()
        self.check_levels()
        self.check_sections_against_levels()
        self.check_nodes()
        self.full_check()

    # -- section 2 ----------------------------------------------------------------------

    def check_header(self):
        data = self.data
        if len(data) < HEADER_SIZE:
            raise FormatError(
                "header",
                f"the file is {len(data)} bytes, shorter than the {HEADER_SIZE}-byte header",
            )
        h = dict(zip(HEADER_FIELDS, HEADER.unpack_from(data, 0)))
        self.header = h
        if h["magic"] != MAGIC:
            raise FormatError(
                "header",
                f"bad magic {h['magic'].hex(' ')} (expected {MAGIC.hex(' ')}): "
                "not a .mdlod file",
            )
        major, minor = h["version_major"], h["version_minor"]
        if not MAJOR_MIN <= major <= MAJOR_MAX:
            hint = "upgrade the reader" if major > MAJOR_MAX else "the file is too old"
            raise FormatError(
                "header",
                f"format version {major}.{minor}, this reader reads major versions "
                f"{MAJOR_MIN} to {MAJOR_MAX} ({hint})",
            )
        actual = xxh3_64(data[:56])
        if actual != h["header_checksum"]:
            raise FormatError(
                "header",
                f"header checksum mismatch (stored {h['header_checksum']:#018x}, "
                f"bytes 0..56 hash to {actual:#018x}): the header is corrupt",
            )
        if h["file_size"] != len(data):
            raise FormatError(
                "header",
                f"file_size says {h['file_size']} bytes but the file has {len(data)} "
                f"({'truncated' if len(data) < h['file_size'] else 'extra bytes'})",
            )
        if h["position_bits"] not in (8, 16):
            raise FormatError(
                "header", f"position_bits {h['position_bits']} (must be 8 or 16)"
            )
        # flags and reserved are written 0 and not checked (section 2).

    # -- section 3 ----------------------------------------------------------------------

    def check_section_table(self):
        h = self.header
        table, count = h["section_table_offset"], h["section_count"]
        place = "section table"
        if count > MAX_SECTIONS:
            raise FormatError(place, f"section_count {count} (at most {MAX_SECTIONS})")
        if table % 64 != 0 or table < HEADER_SIZE:
            raise FormatError(
                place, f"section_table_offset {table} is not a multiple of 64 that is ≥ 64"
            )
        end = table + 32 * count
        if end > h["file_size"]:
            raise FormatError(
                place,
                f"{count} entries at offset {table} end at byte {end}, "
                f"beyond the end of the file ({h['file_size']})",
            )
        self.table_end = end
        raw = self.data[table:end]
        actual = xxh3_64(raw)
        if actual != h["section_table_checksum"]:
            raise FormatError(
                place,
                f"section table checksum mismatch (stored "
                f"{h['section_table_checksum']:#018x}, the table hashes to "
                f"{actual:#018x}): the section table is corrupt",
            )
        self.sections = []
        for i, values in enumerate(SECTION.iter_unpack(raw)):
            s = dict(zip(SECTION_FIELDS, values))
            s["index"] = i
            where = f"section table entry {i} ({self.describe(s)})"
            if s["offset"] % 64 != 0 or s["offset"] < HEADER_SIZE:
                raise FormatError(
                    where, f"offset {s['offset']} is not a multiple of 64 that is ≥ 64"
                )
            if s["offset"] + s["length"] > table:
                raise FormatError(
                    where,
                    f"bytes {s['offset']}..{s['offset'] + s['length']} do not lie "
                    f"before the section table (offset {table})",
                )
            self.sections.append(s)
        by_offset = sorted(self.sections, key=lambda s: (s["offset"], s["length"]))
        for a, b in zip(by_offset, by_offset[1:]):
            if a["offset"] + a["length"] > b["offset"]:
                raise FormatError(
                    place,
                    f"entry {a['index']} ({self.describe(a)}) and entry {b['index']} "
                    f"({self.describe(b)}) overlap",
                )
        self.used = {}

    # A reader uses METADATA, LEVELS and NODES whatever their level field says (writers
    # write 0), POSITIONS of levels 1 to L - 1, SPECIES, ATTRIBUTE and RADIUS of level
    # L - 1. It
    # skips every other section: unknown kinds and known kinds at other levels. A
    # section it uses must be the only one of its kind (and level, for per-level kinds).

    def find(self, kind, level=None):
        """The section of `kind` (at `level` for per-level kinds), or None."""
        found = [
            s
            for s in self.sections
            if s["kind"] == kind and (level is None or s["level"] == level)
        ]
        if len(found) > 1:
            raise FormatError(
                "section table",
                f"two {self.describe(found[0])} sections (entries {found[0]['index']} "
                f"and {found[1]['index']})",
            )
        if found:
            self.used[(kind, level or 0)] = found[0]
            return found[0]
        return None

    def require(self, kind, level=None):
        s = self.find(kind, level)
        if s is None:
            where = "" if level is None else f" for level {level}"
            raise FormatError("section table", f"no {KIND_NAMES[kind]} section{where}")
        return s

    @staticmethod
    def describe(s):
        name = KIND_NAMES.get(s["kind"], f"unknown kind {s['kind']}")
        return f"{name} level {s['level']}" if s["kind"] in PER_LEVEL_KINDS else name

    def section_bytes(self, s):
        """The `length` bytes of section entry `s`, after checking their checksum."""
        raw = self.data[s["offset"] : s["offset"] + s["length"]]
        actual = xxh3_64(raw)
        if actual != s["checksum"]:
            raise FormatError(
                f"{self.describe(s)} section (entry {s['index']}, offset {s['offset']})",
                f"checksum mismatch (stored {s['checksum']:#018x}, the bytes hash to "
                f"{actual:#018x}): the section is corrupt",
            )
        return raw

    # -- section 7: metadata ------------------------------------------------------------

    def check_metadata(self):
        s = self.require(METADATA)
        place = "METADATA"
        if s["length"] > METADATA_MAX:
            raise FormatError(place, f"{s['length']} bytes, more than 16 MiB")
        raw = self.section_bytes(s)
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as e:
            raise FormatError(place, f"not UTF-8 ({e})") from None

        def no_constant(name):
            raise ValueError(f"{name} is not JSON")

        try:
            meta = json.loads(text, object_pairs_hook=JsonObject, parse_constant=no_constant)
        except (ValueError, RecursionError) as e:
            raise FormatError(place, f"invalid JSON ({e})") from None
        if not isinstance(meta, dict):
            raise FormatError(place, "not a JSON object")
        check_fields(meta, METADATA_FIELDS, "")
        self.metadata = meta
        species = meta["species"]
        if not 1 <= len(species) <= 65535:
            raise FormatError(place, f"{len(species)} species (must be 1 to 65535)")
        for sp in species:
            r = sp.get("radius_range")
            if r is not None:
                lo, hi = f32(r[0]), f32(r[1])
                if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
                    raise FormatError(
                        place,
                        f"species {sp['name']!r}: radius_range {r} (must be two positive "
                        "numbers, the smaller first)",
                    )
        # The radii and the attribute range are single precision (f32) numbers.
        self.radii = [f32(sp["radius"]) for sp in species]
        self.attribute = None
        if meta.get("attribute") is not None:
            self.attribute = (f32(meta["attribute"]["min"]), f32(meta["attribute"]["max"]))
        # Further attributes: at most 64 (counted first), ranges, distinct names after
        # a first one.
        self.extras = meta.get("attributes") or []
        if len(self.extras) > MAX_EXTRA_ATTRIBUTES:
            raise FormatError(
                place,
                f"{len(self.extras)} extra attributes (at most {MAX_EXTRA_ATTRIBUTES})",
            )
        names = [meta["attribute"]["name"]] if meta.get("attribute") is not None else []
        for k, a in enumerate(self.extras):
            lo, hi = f32(a["min"]), f32(a["max"])
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise FormatError(
                    place,
                    f"attributes[{k}] {a['name']!r}: range {lo} to {hi} (must be two finite "
                    "numbers, the smaller first)",
                )
            if not names:
                raise FormatError(
                    place,
                    f"attributes[{k}] {a['name']!r}: an extra attribute without a first "
                    "(`attribute`)",
                )
            if a["name"] in names:
                raise FormatError(place, f"attributes[{k}] {a['name']!r}: a name given twice")
            names.append(a["name"])
        # A frame's checksum is 16 lowercase hexadecimal digits.
        source = meta.get("source") or {}
        xxh3 = (source.get("bytes") or {}).get("xxh3")
        if xxh3 is not None and not (
            len(xxh3) == 16 and all(c in "0123456789abcdef" for c in xxh3)
        ):
            raise FormatError(
                place,
                f"source.bytes.xxh3 {xxh3[:40]!r} is not 16 lowercase hexadecimal digits",
            )
        # Per-particle radii: linear steps (`radius`, RADIUS) or a log scale
        # (`radius_log`, RADIUS_LOG), not both.
        self.radius_range = None
        self.radius_log = meta.get("radius_log") is not None
        if self.radius_log and meta.get("radius") is not None:
            raise FormatError(
                place, "gives both `radius` and `radius_log` (the radii are quantized one way)"
            )
        field = "radius_log" if self.radius_log else "radius"
        if meta.get(field) is not None:
            lo, hi = f32(meta[field]["min"]), f32(meta[field]["max"])
            least_ok = lo > 0 if self.radius_log else lo >= 0
            if not (math.isfinite(lo) and math.isfinite(hi) and least_ok and lo <= hi):
                raise FormatError(
                    place,
                    f"{field} range {lo} to {hi} (must be two finite numbers "
                    f"{'above 0' if self.radius_log else 'from 0 up'}, the smaller first)",
                )
            self.radius_range = (lo, hi)
        build = meta["build"]
        if build["position_bits"] != self.header["position_bits"]:
            raise FormatError(
                place,
                f"build.position_bits {build['position_bits']} differs from the header's "
                f"{self.header['position_bits']}",
            )
        error = meta["max_position_error"]
        if not (math.isfinite(error) and error >= 0):
            raise FormatError(
                place, f"max_position_error {error} is not a finite number ≥ 0"
            )
        self.delta_n = build["delta_n"]

    # -- section 4: levels --------------------------------------------------------------

    def check_levels(self):
        s = self.require(LEVELS)
        raw = self.section_bytes(s)
        place = "LEVELS"
        if len(raw) % LEVEL.size != 0:
            raise FormatError(place, f"length {len(raw)} is not a multiple of 32")
        L = len(raw) // LEVEL.size
        if not 2 <= L <= MAX_LEVELS:
            raise FormatError(place, f"{L} levels (must be 2 to {MAX_LEVELS})")
        self.levels = []
        total = 0
        for l, (count, node_first, r0, r1) in enumerate(LEVEL.iter_unpack(raw)):
            where = f"LEVELS record {l}"
            if not 1 <= count <= U32_MAX:
                raise FormatError(where, f"point_count {count} (must be 1 to 2^32 - 1)")
            if l == 0 and count != 1:
                raise FormatError(where, f"level 0 has {count} points (must be 1, the top node)")
            if node_first != total:
                raise FormatError(
                    where,
                    f"node_first {node_first} (the points of the levels above sum to {total})",
                )
            # reserved: written 0, not checked (section 4).
            self.levels.append({"point_count": count, "node_first": node_first})
            total += count
        self.L = L
        self.node_count = self.levels[L - 1]["node_first"]
        if self.node_count > U32_MAX:
            raise FormatError(place, f"{self.node_count} nodes, more than 2^32 - 1")
        particles = self.levels[L - 1]["point_count"]
        if self.metadata["particles"] != particles:
            raise FormatError(
                "METADATA",
                f"particles {self.metadata['particles']} differs from the {particles} "
                f"points of level {L - 1}",
            )
        if not 1 <= self.delta_n <= L - 1:
            raise FormatError(
                "METADATA", f"build.delta_n {self.delta_n} (must be 1 to L - 1 = {L - 1})"
            )

    def point_count(self, level):
        return self.levels[level]["point_count"]

    def node_first(self, level):
        return self.levels[level]["node_first"]

    # -- sections 3, 5, 6, 7: which sections there are and their exact lengths -----------

    def check_sections_against_levels(self):
        L, P = self.L, self.point_count(self.L - 1)
        coord_bytes = self.header["position_bits"] // 8
        expected = [(self.require(NODES), 96 * self.node_count)]
        for m in range(1, L):
            expected.append((self.require(POSITIONS, m), self.point_count(m) * 3 * coord_bytes))
        expected.append((self.require(SPECIES, L - 1), 2 * P))
        attribute = self.find(ATTRIBUTE, L - 1)
        if attribute is not None and self.attribute is None:
            raise FormatError(
                f"section table entry {attribute['index']} (ATTRIBUTE level {L - 1})",
                "present but the metadata names no attribute",
            )
        if attribute is None and self.attribute is not None:
            raise FormatError(
                "section table",
                f"the metadata names attribute {self.metadata['attribute']['name']!r} but "
                f"there is no ATTRIBUTE section for level {L - 1}",
            )
        if attribute is not None:
            expected.append((attribute, 2 * P))
        kind, other = (RADIUS_LOG, RADIUS) if self.radius_log else (RADIUS, RADIUS_LOG)
        field = "radius_log" if self.radius_log else "radius"
        radius = self.find(kind, L - 1)
        if (radius is None) != (self.radius_range is None):
            raise FormatError(
                "section table",
                f"a {KIND_NAMES[kind]} section is present but the metadata gives no "
                f"{field} range"
                if radius is not None
                else f"the metadata gives a {field} range but there is no "
                f"{KIND_NAMES[kind]} section for level {L - 1}",
            )
        if self.find(other, L - 1) is not None:
            raise FormatError(
                "METADATA",
                f"a {KIND_NAMES[other]} section is present but the metadata gives no "
                f"{'radius' if self.radius_log else 'radius_log'} range",
            )
        if radius is not None:
            expected.append((radius, 2 * P))
        # Further attributes: a u16 per particle and an f32 per node for each.
        k = len(self.extras)
        for kind, level, per in ((ATTRIBUTES, L - 1, 2 * P), (NODE_ATTRIBUTES, 0, 4 * self.node_count)):
            s = self.find(kind, level)
            if s is not None and k == 0:
                raise FormatError(
                    "METADATA",
                    f"{KIND_NAMES[kind]} is present but the metadata lists no `attributes`",
                )
            if s is None and k > 0:
                raise FormatError(
                    "section table",
                    f"the metadata lists {k} `attributes` but there is no "
                    f"{KIND_NAMES[kind]} section",
                )
            if s is not None:
                expected.append((s, per * k))
        for s, length in expected:
            if s["length"] != length:
                raise FormatError(
                    f"{self.describe(s)} section (entry {s['index']})",
                    f"length {s['length']} (expected {length})",
                )

    # -- section 5: nodes ---------------------------------------------------------------

    def check_nodes(self):
        """Every node record against the constraints of sections 4 and 5."""
        raw = self.section_bytes(self.used[(NODES, 0)])
        L, dn = self.L, self.delta_n
        species_count = len(self.metadata["species"])
        nodes = [Node(r) for r in (raw[i : i + 96] for i in range(0, len(raw), 96))]
        self.nodes = nodes
        # parent_of[l + 1][i]: node index of the parent of point i of level l + 1.
        self.parent_of = [None] * L
        for l in range(L - 1):
            first, count = self.node_first(l), self.point_count(l)
            below = self.point_count(l + 1)
            parents = []
            next_child = 0
            for i in range(count):
                n = first + i
                node = nodes[n]
                where = f"NODES: node {n} (level {l}, point {i})"
                if node.level != l:
                    raise FormatError(where, f"level field {node.level} (must be {l})")
                bad = [x for x in node.floats() if not math.isfinite(x)]
                if bad:
                    raise FormatError(where, f"non-finite value {bad[0]}")
                if node.radius < 0:
                    raise FormatError(where, f"negative radius {node.radius}")
                if min(node.quant_scale) < 0:
                    raise FormatError(where, f"negative quant_scale {node.quant_scale}")
                if node.area_sum < 0:
                    raise FormatError(where, f"negative area_sum {node.area_sum}")
                if any(lo > hi for lo, hi in zip(node.bounds_min, node.bounds_max)):
                    raise FormatError(
                        where, f"bounds_max {node.bounds_max} below bounds_min {node.bounds_min}"
                    )
                if node.child_count < 1:
                    raise FormatError(where, "child_count 0")
                if node.child_first != next_child:
                    raise FormatError(
                        where,
                        f"children start at {node.child_first}, expected {next_child} "
                        "(where the previous node's children end)",
                    )
                next_child = node.child_first + node.child_count
                if next_child > below:
                    raise FormatError(
                        where,
                        f"children {node.child_first}..{next_child} run past the "
                        f"{below} points of level {l + 1}",
                    )
                parents.extend([n] * node.child_count)
                expect_parent = NO_NODE if l == 0 else self.parent_of[l][i]
                if node.parent != expect_parent:
                    raise FormatError(
                        where,
                        f"parent {node.parent} (the node whose children include it is "
                        f"{expect_parent})",
                    )
                point_level = min(l + dn, L - 1)
                if node.point_level != point_level:
                    raise FormatError(
                        where, f"point_level {node.point_level} (must be {point_level})"
                    )
                if node.point_count < 1 or (
                    node.point_first + node.point_count > self.point_count(point_level)
                ):
                    raise FormatError(
                        where,
                        f"points {node.point_first}+{node.point_count} do not lie within "
                        f"the {self.point_count(point_level)} points of level {point_level}",
                    )
                quant_level = max(0, point_level - dn)
                ancestor = self.ancestor(n, l, quant_level)
                if node.quant_node != ancestor:
                    raise FormatError(
                        where,
                        f"quant_node {node.quant_node} (its ancestor on level "
                        f"{quant_level} is {ancestor})",
                    )
                if node.species >= species_count:
                    raise FormatError(
                        where, f"species {node.species} (there are {species_count} species)"
                    )
            if next_child != below:
                raise FormatError(
                    f"NODES: level {l}",
                    f"the children of its nodes cover {next_child} of the {below} points "
                    f"of level {l + 1}",
                )
            self.parent_of[l + 1] = parents

    def ancestor(self, node, level, target):
        """The node index of the ancestor on level `target` of node `node` of `level`."""
        while level > target:
            node = self.parent_of[level][node - self.node_first(level)]
            level -= 1
        return node

    def point_ancestor(self, m, i, target):
        """The node index of the ancestor on level `target` < m of point i of level m."""
        node = self.parent_of[m][i]
        return self.ancestor(node, m - 1, target)

    def descendants(self, node, level, target):
        """Section 6: the range [a, b) of the descendants on level `target` of a node."""
        a = node - self.node_first(level)
        b = a + 1
        while level < target:
            first = self.node_first(level)
            last = self.nodes[first + b - 1]
            a = self.nodes[first + a].child_first
            b = last.child_first + last.child_count
            level += 1
        return a, b

    # -- section 8: what the full check adds --------------------------------------------

    def full_check(self):
        # Every section's checksum, unknown kinds' too.
        for s in self.sections:
            self.section_bytes(s)
        # Padding: every byte outside the header, the sections and the table is zero,
        # bytes after the table (writers write none) included.
        used = [(s["offset"], s["offset"] + s["length"]) for s in self.sections]
        used.append((self.header["section_table_offset"], self.table_end))
        used.append((len(self.data), len(self.data)))
        at = HEADER_SIZE
        for start, end in sorted(used):
            if start > at and self.data[at:start].count(0) != start - at:
                raise FormatError(f"padding bytes {at}..{start}", "not all zero")
            at = max(at, end)
        # Species indices.
        species_count = len(self.metadata["species"])
        self.species = self.u16_array(self.used[(SPECIES, self.L - 1)])
        for i, sp in enumerate(self.species):
            if sp >= species_count:
                raise FormatError(
                    f"SPECIES: particle {i}", f"species {sp} (there are {species_count})"
                )
        self.attribute_q = None
        if self.attribute is not None:
            self.attribute_q = self.u16_array(self.used[(ATTRIBUTE, self.L - 1)])
        # Further attributes: values per particle, means per node (finite).
        self.extra_q, self.extra_means = [], []
        if self.extras:
            if self.header["version_minor"] < 2:
                raise FormatError(
                    "header",
                    f"version {self.header['version_major']}.{self.header['version_minor']} "
                    "holds an ATTRIBUTES section, which version 1.2 added",
                )
            q = self.u16_array(self.used[(ATTRIBUTES, self.L - 1)])
            raw = self.section_bytes(self.used[(NODE_ATTRIBUTES, 0)])
            means = [v for (v,) in struct.iter_unpack("<f", raw)]
            P, N = self.point_count(self.L - 1), self.node_count
            for k, a in enumerate(self.extras):
                self.extra_q.append(q[k * P : (k + 1) * P])
                self.extra_means.append(means[k * N : (k + 1) * N])
                for i, m in enumerate(self.extra_means[-1]):
                    if not math.isfinite(m):
                        raise FormatError(
                            f"NODE_ATTRIBUTES, attribute {a['name']!r}, node {i}",
                            "mean is not finite",
                        )
        self.radius_q = None
        if self.radius_range is not None:
            kind, since = (RADIUS_LOG, 2) if self.radius_log else (RADIUS, 1)
            self.radius_q = self.u16_array(self.used[(kind, self.L - 1)])
            if self.header["version_minor"] < since:
                raise FormatError(
                    "header",
                    f"version {self.header['version_major']}.{self.header['version_minor']} "
                    f"holds a {KIND_NAMES[kind]} section, which version 1.{since} added",
                )
        # Every node's drawn range is exactly its descendants on point_level.
        for l in range(self.L - 1):
            for i in range(self.point_count(l)):
                n = self.node_first(l) + i
                node = self.nodes[n]
                a, b = self.descendants(n, l, node.point_level)
                if (node.point_first, node.point_count) != (a, b - a):
                    raise FormatError(
                        f"NODES: node {n} (level {l}, point {i})",
                        f"point_first/point_count {node.point_first}/{node.point_count}, "
                        f"but its descendants on level {node.point_level} are "
                        f"{a}..{b}",
                    )
        self.own_radii = self.radius_values() if self.radius_q is not None else None
        # The decoding of every point: finite and inside its parent's bounds.
        self.positions = [self.decode_level(m) for m in range(self.L)]
        for m in range(1, self.L):
            self.check_decoded(m)

    def u16_array(self, s):
        raw = self.section_bytes(s)
        return [v for (v,) in struct.iter_unpack("<H", raw)]

    # -- section 6: decoding ------------------------------------------------------------

    def decode_level(self, m):
        """The positions of the points of level `m`, as (x, y, z) of f32 values."""
        if m == 0:
            return [self.nodes[0].centroid]
        bits = self.header["position_bits"]
        H = (2**bits - 1) / 2  # 32767.5 or 127.5, exact in f32
        fmt = "<3B" if bits == 8 else "<3H"
        raw = self.section_bytes(self.used[(POSITIONS, m)])
        encoder_level = max(0, m - self.delta_n)
        out = []
        for i, q in enumerate(struct.iter_unpack(fmt, raw)):
            A = self.nodes[self.point_ancestor(m, i, encoder_level)]
            # position[k] = A.centroid[k] + A.quant_scale[k] * (q[k] - H), in f32:
            # multiply, round, add, round (q - H is exact).
            out.append(
                tuple(
                    f32(A.centroid[k] + f32(A.quant_scale[k] * (q[k] - H)))
                    for k in range(3)
                )
            )
        return out

    def check_decoded(self, m):
        """Section 8, full check: every decoded point of level m is finite and lies
        inside its parent's bounds up to the encoding node's step (plus a tolerance); a
        particle also inside those bounds shrunk by its species radius, up to
        max_position_error (plus the bounds' single-precision rounding). The arithmetic
        is binary64, on the f32 values."""
        particles = m == self.L - 1
        error = self.metadata["max_position_error"]
        encoder_level = max(0, m - self.delta_n)
        for i, x in enumerate(self.positions[m]):
            where = f"POSITIONS level {m}: point {i}"
            if not all(math.isfinite(c) for c in x):
                raise FormatError(where, f"decodes to a non-finite position {x}")
            parent = self.nodes[self.parent_of[m][i]]
            encoder = self.nodes[self.point_ancestor(m, i, encoder_level)]
            lo, hi = parent.bounds_min, parent.bounds_max
            outside = max(max(lo[k] - x[k], x[k] - hi[k]) for k in range(3))
            if outside - max(encoder.quant_scale) > 1e-3 * (1 + parent.radius):
                raise FormatError(
                    where,
                    f"decodes to {x}, {outside} outside its parent's bounds {lo}..{hi} "
                    f"(more than the step {max(encoder.quant_scale)} of its encoding node "
                    f"+ 1e-3 * (1 + {parent.radius}))",
                )
            if not particles:
                continue
            # Its own radius (RADIUS), else its species'; an own radius lies within its
            # species' sizes (radius_range, else its radius) up to a quantization step.
            sp = self.metadata["species"][self.species[i]]
            if self.radius_q is not None:
                r = self.own_radii[i]
                s_lo, s_hi = (
                    (f32(sp["radius_range"][0]), f32(sp["radius_range"][1]))
                    if sp.get("radius_range") is not None
                    else (self.radii[self.species[i]],) * 2
                )
                lo_r, hi_r = self.radius_range
                if self.radius_log:
                    step = s_hi * ((hi_r / lo_r) ** (1 / 65535) - 1)
                else:
                    step = (hi_r - lo_r) / 65535
                slack = step + 8 * 2.0**-23 * s_hi
                if r < s_lo - slack or r > s_hi + slack:
                    raise FormatError(
                        f"RADIUS: particle {i}",
                        f"radius {r} lies outside its species' sizes {s_lo} to {s_hi}",
                    )
            else:
                r = self.radii[self.species[i]]
            beyond, wider, size = 0.0, 0.0, r
            for k in range(3):
                # Where its centre lies: the bounds shrunk by r, or the box's middle
                # where it is narrower than the sphere.
                if hi[k] - lo[k] >= 2 * r:
                    a, b = lo[k] + r, hi[k] - r
                else:
                    a = b = (lo[k] + hi[k]) / 2
                beyond = max(beyond, a - x[k], x[k] - b)
                wider = max(wider, 2 * r - (hi[k] - lo[k]))
                size = max(size, abs(lo[k]), abs(hi[k]))
            rounding = 8 * 2.0**-23 * size
            if wider > 2 * (error + rounding):
                raise FormatError(
                    where,
                    f"its sphere (radius {r}) is {wider:.3e} wider than its parent's bounds "
                    f"{lo}..{hi} on an axis: more than 2 * (max_position_error + "
                    f"8 * 2^-23 * {size})",
                )
            if beyond > error + rounding:
                raise FormatError(
                    where,
                    f"decodes to {x}, {beyond:.3e} beyond its parent's bounds {lo}..{hi} "
                    f"shrunk by its radius {r}: more than max_position_error {error:.3e} "
                    f"+ 8 * 2^-23 * {size}",
                )

    def radius_values(self):
        """Section 7: r = min + (max - min) * (q / 65535), in f32; on a log scale
        (RADIUS_LOG) r = min * (max / min) ** (q / 65535), in f64 rounded to f32."""
        lo, hi = self.radius_range
        if self.radius_log:
            return [f32(lo * (hi / lo) ** (q / 65535)) for q in self.radius_q]
        span = f32(hi - lo)
        return [f32(lo + f32(span * f32(q / 65535))) for q in self.radius_q]

    def attribute_values(self):
        """Section 7: value = min + (max - min) * (q / 65535), in f32."""
        lo, hi = self.attribute
        span = f32(hi - lo)
        return [f32(lo + f32(span * f32(q / 65535))) for q in self.attribute_q]

    # -- output -------------------------------------------------------------------------

    def to_json(self):
        h = dict(self.header)
        h["magic"] = h["magic"].hex()
        L = self.L
        levels = [
            {
                "level": l,
                "point_count": rec["point_count"],
                "node_first": rec["node_first"],
                "positions": [list(p) for p in self.positions[l]],
            }
            for l, rec in enumerate(self.levels)
        ]
        particles = {
            "level": L - 1,
            "count": self.point_count(L - 1),
            "positions": levels[L - 1]["positions"],
            "species": self.species,
            "attribute": None,
            "radius": None,
        }
        if self.radius_q is not None:
            particles["radius"] = {"q": self.radius_q, "values": self.own_radii}
        if self.attribute is not None:
            particles["attribute"] = {
                "name": self.metadata["attribute"]["name"],
                "q": self.attribute_q,
                "values": self.attribute_values(),
            }
        particles["attributes"] = [
            {
                "name": a["name"],
                "q": q,
                "values": [
                    f32(f32(a["min"]) + f32(f32(f32(a["max"]) - f32(a["min"])) * f32(v / 65535)))
                    for v in q
                ],
                "node_means": means,
            }
            for a, q, means in zip(self.extras, self.extra_q, self.extra_means)
        ]
        return {
            "file": self.path,
            "header": h,
            "sections": [
                {"name": self.describe(s), **{k: s[k] for k in SECTION_FIELDS}}
                for s in self.sections
            ],
            "metadata": self.metadata,
            "levels": levels,
            "nodes": [n.to_json() for n in self.nodes],
            "particles": particles,
        }


def main(argv=None):
    parser = argparse.ArgumentParser(
        description="Validate a .mdlod file and decode every point (FORMAT.md's companion)."
    )
    parser.add_argument("file", help="the .mdlod file")
    parser.add_argument("--dump", metavar="OUT.json", help="write the decoded file as JSON")
    args = parser.parse_args(argv)
    try:
        f = MdlodFile(args.file)
    except FormatError as e:
        sys.stderr.write(f"{args.file}: {e}\n")
        return 1
    except OSError as e:
        sys.stderr.write(f"{args.file}: cannot read: {e.strerror or e}\n")
        return 1
    except Exception as e:  # a bug of this reader, not of the file: no traceback either
        sys.stderr.write(f"{args.file}: read_mdlod.py failed ({type(e).__name__}: {e})\n")
        return 2
    if args.dump:
        try:
            with open(args.dump, "w", encoding="utf-8") as out:
                json.dump(f.to_json(), out, allow_nan=False)
        except OSError as e:
            sys.stderr.write(f"{args.dump}: cannot write: {e.strerror or e}\n")
            return 1
    h = f.header
    print(
        f"{args.file}: mdlod {h['version_major']}.{h['version_minor']}, "
        f"{f.point_count(f.L - 1)} particles, {f.L} levels, {f.node_count} nodes, "
        f"{h['position_bits']}-bit positions, delta_n {f.delta_n}: valid"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
