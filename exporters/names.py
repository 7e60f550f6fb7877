"""Names in the written files, derived from the object's name as the user wrote it.

A user's name ("cabinet door", "Müller's mug (v2)", "ハンマー", "drawer #3 / left")
is kept unchanged in asset.json and wherever a format has a free-text field (an
XML comment, USD customData and `doc`). Everything a loader looks up by name, and
the output file names, are derived here, so that the writers and the checks in
pipelines/validate.py agree on them. Every function is deterministic (a pure
function of the text) and leaves an already-safe name unchanged ("cube",
"cabinet_door"), so existing outputs keep their names.

Body, link, joint and prim names: one ASCII identifier, [A-Za-z_][A-Za-z0-9_]*,
the same in every format so that the body carries one name across files:

- USD: `Sdf.Path.IsValidIdentifier`. usd-core 24.03 and later also take UTF-8
  identifiers, but older readers (and the tools built on them) reject them, and
  `Tf.MakeValidIdentifier` maps UTF-8 byte by byte ("Müller" -> "M__ller").
- MJCF: MuJoCo takes any string, except "world" (body 0's name). Newton's MJCF
  importer rewrites "-" to "_" in body and joint names (a lookup by the written
  name then misses) and builds labels "model/worldbody/body" that a "/" in a
  name would split.
- URDF: yourdfpy and MuJoCo's URDF compiler take any non-empty string. Newton's
  URDF importer labels bodies "robot/link", split by the same "/". ROS names
  are ASCII letters, digits and "_", and Gazebo and ROS tools treat a link
  named "world" as the fixed world frame.

Accented Latin letters are transliterated (NFKD, then the base letter); other
letters that have no ASCII form are dropped and an 8-digit hash of the name is
appended, so that "ハンマー" and "ドライバー" stay distinct. A name with
nothing left is "object".

File stems keep the user's text (any script, spaces) and replace only what
breaks a file system or a reference to the file; see `file_stem`.
"""

from __future__ import annotations

import hashlib
import re
import unicodedata
from dataclasses import dataclass

__all__ = ["FALLBACK", "MAX_STEM_BYTES", "FormatNames", "base_name", "file_stem", "joint_name", "mjcf_name",
           "urdf_name", "usd_prim_name", "xml_comment_text"]

FALLBACK = "object"
"""The identifier (and file stem) of a name with nothing usable in it, such as "" or "  "."""

MAX_STEM_BYTES = 128
"""File systems allow 255 bytes (ext4, APFS) or 255 UTF-16 units (NTFS) per name; the rest is headroom
for the extension and for suffixes other tools add."""

_NOT_IDENTIFIER_CHARS = re.compile(r"[^A-Za-z0-9_]+")

# Latin letters NFKD does not decompose; each has a usual ASCII spelling.
_LATIN = str.maketrans({"ß": "ss", "ẞ": "SS", "æ": "ae", "Æ": "AE", "œ": "oe", "Œ": "OE", "ø": "o", "Ø": "O",
                        "ł": "l", "Ł": "L", "đ": "d", "Đ": "D", "ð": "d", "Ð": "D", "þ": "th", "Þ": "Th",
                        "ı": "i", "ħ": "h", "Ħ": "H"})

# Reserved by MuJoCo (body 0) and, for URDF, by Gazebo's and ROS's convention for the fixed world frame.
_WORLD_NAMES = frozenset({"world"})

# Not allowed in Windows file names, plus "#" and "%" (they begin a fragment and an escape once the path
# becomes a URI: package://, file://, href) and "@" (it delimits USD asset paths, @NAME.usda@).
_UNSAFE_IN_STEM = frozenset('/\\:*?"<>|#%@')
# Windows refuses these as a file's name before its first dot, in any case ("con.urdf", "Com1.xml").
_WINDOWS_RESERVED = frozenset(
    {"CON", "PRN", "AUX", "NUL", "CONIN$", "CONOUT$"}
    | {f"{port}{n}" for port in ("COM", "LPT") for n in (*"0123456789", "¹", "²", "³")}
)
# Joiners are part of how some scripts and emoji are written; other format characters (bidirectional
# overrides) can make a file name display as something else.
_JOINERS = frozenset("\u200c\u200d")
_UNSAFE_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Zl", "Zp"})
_LEADING = re.compile(r"\A\s+")
_TRAILING = re.compile(r"[\s.]+\Z")


def _digest(name: str) -> str:
    """8 hex digits of the name's SHA-256; NFC first, so that a name typed composed or decomposed ("ü",
    "u" + combining diaeresis) is one name."""
    return hashlib.sha256(unicodedata.normalize("NFC", name).encode("utf-8", "surrogatepass")).hexdigest()[:8]


def _identifier(name: str) -> str:
    """The ASCII identifier of `name` shared by every format (module docstring)."""
    ascii_chars, lost = [], False
    for c in unicodedata.normalize("NFKD", name.translate(_LATIN)):
        if c.isascii():
            ascii_chars.append(c)
        elif unicodedata.category(c)[0] in "LN":
            lost = True
        elif unicodedata.category(c)[0] != "M":  # marks are the accents NFKD split off their letters
            ascii_chars.append(" ")
    # a run of other characters becomes one "_"; at either end it is dropped ("(v2)" -> "v2")
    core = "_".join(w for w in _NOT_IDENTIFIER_CHARS.split("".join(ascii_chars)) if w)
    if lost:
        core = f"{core or FALLBACK}_{_digest(name)}"
    core = core or FALLBACK
    return f"_{core}" if core[0].isdigit() else core


def usd_prim_name(name: str) -> str:
    """A USD prim name for `name`: valid per `Sdf.Path.IsValidIdentifier`, ASCII only."""
    return _identifier(name)


def mjcf_name(name: str) -> str:
    """The MJCF body name for `name` (also the model name and the prefix of its joint and base names)."""
    return _not_world(_identifier(name))


def urdf_name(name: str) -> str:
    """The URDF link name for `name` (also the robot name and the prefix of its joint and base names)."""
    return _not_world(_identifier(name))


def _not_world(identifier: str) -> str:
    return f"{identifier}_" if identifier in _WORLD_NAMES else identifier


def joint_name(body: str) -> str:
    """The joint of a jointed part named `body` (an MJCF or URDF name from above)."""
    return f"{body}_joint"


def base_name(body: str) -> str:
    """The fixed base body (MJCF) or link (URDF) a jointed part named `body` hangs from."""
    return f"{body}_base"


def file_stem(name: str) -> str:
    """A file name without extension for `name`, safe on Linux, macOS and Windows.

    The user's text is kept (NFC, the form macOS and Linux then agree on) except:
    runs of characters unsafe in a file name or in a URI or USD reference to it
    (`/ \\ : * ? " < > | # % @`), control, format (bidirectional overrides),
    surrogate and line or paragraph separator characters become one "_";
    surrounding white space and trailing dots go (Windows drops them, so two
    names would meet); a leading "." (hidden file, "..") or "-" (read as an
    option by command-line tools) gets a "_" before it; Windows' reserved
    device names (CON, NUL, COM1, ...) get a "_" after them; an empty result
    is "object"; over `MAX_STEM_BYTES` of UTF-8 the text is cut and a hash of
    the whole name appended.
    """
    out, in_run = [], False
    for c in unicodedata.normalize("NFC", name):
        unsafe = c in _UNSAFE_IN_STEM or (unicodedata.category(c) in _UNSAFE_CATEGORIES and c not in _JOINERS)
        if not unsafe:
            out.append(c)
        elif not in_run:
            out.append("_")
        in_run = unsafe
    stem = _TRAILING.sub("", _LEADING.sub("", "".join(out)))
    if stem[:1] in (".", "-"):
        stem = "_" + stem
    stem = stem or FALLBACK
    base = stem.partition(".")[0].rstrip(" ")
    if base.upper() in _WINDOWS_RESERVED:
        stem = f"{base}_{stem[len(base):]}"
    if len(stem.encode("utf-8")) > MAX_STEM_BYTES:
        suffix = "_" + _digest(name)
        head = stem.encode("utf-8")[: MAX_STEM_BYTES - len(suffix)].decode("utf-8", "ignore")
        stem = _TRAILING.sub("", head) + suffix
    return stem


def xml_comment_text(name: str) -> str:
    """`name` as text that may stand inside an XML comment: no "--", and characters XML 1.0 forbids
    (and line breaks, to keep the comment on one line) written as \\uXXXX."""

    def allowed(c: str) -> bool:
        o = ord(c)
        return 0x20 <= o <= 0xD7FF or 0xE000 <= o <= 0xFFFD or o >= 0x10000

    text = "".join(c if allowed(c) else f"\\u{ord(c):04x}" for c in name)
    return re.sub(r"-(?=-|\Z)", "- ", text)


@dataclass(frozen=True)
class FormatNames:
    """Every name derived from one user's name; `name` is that name unchanged."""

    name: str
    usd: str
    mjcf: str
    urdf: str
    file: str

    @classmethod
    def of(cls, name: str) -> FormatNames:
        return cls(name, usd_prim_name(name), mjcf_name(name), urdf_name(name), file_stem(name))
