"""The material library: density and friction ranges with their sources (materials.json).

Free-text hints ('solid beech wood', 'painted MDF') are read into its keys by `match_material`.

Every range is a triple (central, low, high): low..high is a credible range of
about 95 %, and the priors read it as a log-normal whose median is the central
value (`pipelines.priors`).
"""

from __future__ import annotations

import difflib
import json
import re
import unicodedata
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Literal

LIBRARY_PATH = Path(__file__).with_name("materials.json")
UNKNOWN = "unknown"

Structure = Literal["solid", "printed", "shell"]
STRUCTURES: tuple[str, ...] = ("solid", "printed", "shell")


@dataclass(frozen=True)
class MaterialRange:
    """A material's density [kg/m^3] and Coulomb friction (unitless): central value and credible range.

    density*: bulk density of an object of this material (mass / enclosed volume).
    friction*: static coefficient against common surfaces; friction_kinetic*: the sliding one.
    structure: how the geometry prior fills the mesh: "solid"; "printed" (walls plus a
      partial infill of `solid_density`); "shell" (hollow, walls of `wall_m` of `solid_density`).
    solid_density: (central, low, high) [kg/m^3] of the wall material, or None (= density).
    wall_m: (central, low, high) wall thickness [m] of a shell, or None.
    """

    name: str
    density: float
    density_low: float
    density_high: float
    friction: float
    friction_low: float
    friction_high: float
    source: str
    friction_kinetic: float | None = None
    friction_kinetic_low: float | None = None
    friction_kinetic_high: float | None = None
    structure: Structure = "solid"
    solid_density: tuple[float, float, float] | None = None
    wall_m: tuple[float, float, float] | None = None
    category: str = ""

    def wall_density(self) -> tuple[float, float, float]:
        """(central, low, high) [kg/m^3] of the material the walls (or the whole solid) are made of."""
        if self.solid_density is not None:
            return self.solid_density
        return (self.density, self.density_low, self.density_high)

    def kinetic(self) -> tuple[float, float, float]:
        """(central, low, high) kinetic friction; 0.8 x the static range where the library gives none."""
        if self.friction_kinetic is None:
            return (0.8 * self.friction, 0.8 * self.friction_low, 0.8 * self.friction_high)
        return (self.friction_kinetic, self.friction_kinetic_low, self.friction_kinetic_high)


@cache
def _library() -> dict:
    try:
        lib = json.loads(LIBRARY_PATH.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{LIBRARY_PATH}: cannot read the material library ({exc})") from exc
    for key, entry in {**lib["materials"], UNKNOWN: lib["unknown"]}.items():
        _check_entry(key, entry)
    for alias, key in lib.get("aliases", {}).items():
        if key not in lib["materials"]:
            raise ValueError(f"{LIBRARY_PATH}: alias {alias!r} names no material {key!r}")
    return lib


def _check_entry(key: str, entry: dict) -> None:
    """ValueError naming the file, entry and field when a triple is not (central, low, high) with low <= central <= high."""
    for field in ("density", "friction", "friction_kinetic", "solid_density", "wall_m"):
        if field not in entry:
            if field in ("density", "friction"):
                raise ValueError(f"{LIBRARY_PATH}: material {key!r} has no {field!r}")
            continue
        v = entry[field]
        if not (isinstance(v, list) and len(v) == 3 and 0 < v[1] <= v[0] <= v[2]):
            raise ValueError(f"{LIBRARY_PATH}: material {key!r} field {field!r}: expected [central, low, high] "
                             f"with 0 < low <= central <= high, got {v!r}")
    structure = entry.get("structure", "solid")
    if structure not in STRUCTURES:
        raise ValueError(f"{LIBRARY_PATH}: material {key!r}: structure {structure!r} is not one of {STRUCTURES}")
    if structure == "shell" and "wall_m" not in entry:
        raise ValueError(f"{LIBRARY_PATH}: material {key!r}: a shell needs 'wall_m'")
    if not entry.get("source"):
        raise ValueError(f"{LIBRARY_PATH}: material {key!r} names no source")


def material_names() -> tuple[str, ...]:
    return tuple(sorted(_library()["materials"]))


def _normalise(name: str) -> str:
    return name.strip().lower().replace(" ", "_").replace("-", "_")


def find_material(name: str | None) -> MaterialRange | None:
    """The named material, or None when the library lacks it.

    `name` may be free text ('beech wood', 'painted MDF', 'alumninium'): it is read by
    `match_material` and accepted when the match scores at least MATCH_THRESHOLD.
    """
    if name is None:
        return None
    if _normalise(name) == UNKNOWN:
        return material_range(None)
    match = match_material(name)
    if match.name is None or match.score < MATCH_THRESHOLD:
        return None
    return _from_entry(match.name, _library()["materials"][match.name])


def material_range(name: str | None) -> MaterialRange:
    """The named material, or the wide `unknown` range for None; ValueError names the nearest choices."""
    lib = _library()
    if name is None or name == UNKNOWN:
        return _from_entry(UNKNOWN, lib["unknown"])
    found = find_material(name)
    if found is None:
        nearest = suggest_materials(name)
        hint = f"nearest: {', '.join(nearest)}; or " if nearest else ""
        raise ValueError(f"unknown material {name!r}; {hint}choose one of the keys in "
                         f"{LIBRARY_PATH.parent.name}/{LIBRARY_PATH.name}")
    return found


# Free-text hints. A weak guess (a class word such as 'wood', a spelling fix, words the library does
# not know) scores lower; an explicit name must clear MATCH_THRESHOLD so that a guess never passes
# silently for what the user named.
MATCH_THRESHOLD = 0.7
_SPECIFIC, _GENERIC = 0.95, 0.8  # 'beech wood' vs 'wooden toy': a class word says little about density
_PER_RIVAL = 0.85  # each other material named ('birch plywood', 'steel and wood'): the hint is mixed
_PER_UNKNOWN = 0.9  # each word that is neither a material nor known filler: maybe it changes the material
_SPELLING_CUTOFF = 0.8  # difflib ratio: 'stainles' -> 'stainless' is 0.94, 'wool' -> 'wood' 0.75
_SUGGEST_CUTOFF = 0.7


@dataclass(frozen=True)
class MaterialMatch:
    """How a free-text material hint was read.

    text: the hint as written. name: the library key, or None when no material word was found.
    score: 0..1; 1.0 for a key or a listed alias. how: "exact" (a key), "synonym" (an alias),
    "words" (its words name a key or alias, in any order, with plurals, finishes and filler
    ignored), "spelling" (as "words", after fixing a misspelt word), or "unmatched".
    """

    text: str
    name: str | None
    score: float
    how: str


@dataclass(frozen=True)
class _Phrase:
    text: str  # the key or alias as written in materials.json
    words: frozenset[str]
    name: str
    generic: bool


@dataclass(frozen=True)
class _Word:
    word: str
    known: bool
    ratio: float  # spelling likeness, 1.0 unless fixed
    primary: bool  # False after 'with': 'MDF with oak veneer' is MDF


@dataclass(frozen=True)
class _Vocabulary:
    phrases: tuple[_Phrase, ...]
    stand_ins: dict[str, str]
    generic: frozenset[str]
    ignore: frozenset[str]
    known: frozenset[str]
    material_words: frozenset[str]  # the words of keys and aliases (and their stand-ins), not filler
    spellable: tuple[str, ...]  # sorted, so that difflib breaks ties the same way every run


@cache
def _vocabulary() -> _Vocabulary:
    lib = _library()
    text = lib.get("text", {})
    stand_ins = dict(text.get("words", {}))
    generic = frozenset(text.get("generic", ()))
    ignore = frozenset(text.get("ignore", ()))
    named = {**{key: key for key in lib["materials"]}, **lib.get("aliases", {})}
    phrases = []
    for phrase, name in sorted(named.items()):
        words = frozenset(stand_ins.get(w, w) for w in phrase.split("_"))
        phrases.append(_Phrase(phrase, words, name, words <= generic))
    material_words = frozenset({w for p in phrases for w in p.words} | set(stand_ins))
    known = material_words | ignore
    # Short words are left alone: at three or four letters one typo makes another word ('tiny' / 'tin').
    spellable = tuple(sorted(w for w in known if len(w) >= 5))
    return _Vocabulary(tuple(phrases), stand_ins, generic, ignore, known, material_words, spellable)


def _raw_words(text: str) -> list[str]:
    plain = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode().lower()
    return re.findall(r"[a-z0-9]+", plain)


def _read_word(raw: str, v: _Vocabulary) -> list[tuple[str, float]]:
    """[(known word, spelling likeness)]; [(raw, 0.0)] for a word the library does not know; [] for one to drop."""
    if raw in v.known:
        return [(v.stand_ins.get(raw, raw), 1.0)]
    if len(raw) == 1 or raw.isdigit():
        return []
    if raw.endswith("s"):  # plurals: only to a word the library knows, so 'abs' and 'glass' stay whole
        for stem in (raw[:-3] + "y" if raw.endswith("ies") else None, raw[:-2], raw[:-1]):
            if stem in v.known:
                return [(v.stand_ins.get(stem, stem), 1.0)]
    if any(c.isdigit() for c in raw):  # grades and sizes: '6061', 't6', 'cm3' say nothing of the material
        letters = re.sub(r"\d", "", raw)
        return [(v.stand_ins.get(letters, letters), 1.0)] if letters in v.known else []
    for i in range(3, len(raw) - 2):  # two material words run together: 'beechwood', 'stainlesssteel'
        if raw[:i] in v.material_words and raw[i:] in v.material_words:
            return [(v.stand_ins.get(part, part), 1.0) for part in (raw[:i], raw[i:])]
    if len(raw) >= 4:
        close = difflib.get_close_matches(raw, v.spellable, n=1, cutoff=_SPELLING_CUTOFF)
        if close:
            return [(v.stand_ins.get(close[0], close[0]), difflib.SequenceMatcher(None, raw, close[0]).ratio())]
    return [(raw, 0.0)]


def _read(text: str, v: _Vocabulary) -> list[_Word]:
    words, primary = [], True
    for raw in _raw_words(text):
        if raw == "with":
            primary = False
        words += [_Word(word, ratio > 0.0, ratio, primary) for word, ratio in _read_word(raw, v)]
    return words


def match_material(text: str) -> MaterialMatch:
    """Read a free-text material hint ('solid beech wood', 'painted MDF', 'EPS foam', 'alumninium').

    A key or alias scores 1.0. Otherwise the hint's words are matched against the keys and
    aliases read as sets of words; the most specific set found wins (more words, then a
    material over a class word such as 'foam', then the later word: 'birch plywood' is
    plywood). Finishes, processes, shapes and filler are ignored (materials.json "text").
    """
    lib = _library()
    key = _normalise(text)
    if key in lib["materials"]:
        return MaterialMatch(text, key, 1.0, "exact")
    if key in lib.get("aliases", {}):
        return MaterialMatch(text, lib["aliases"][key], 1.0, "synonym")
    v = _vocabulary()
    words = _read(text, v)
    seen = {w.word for w in words if w.known}
    found = [p for p in v.phrases if p.words <= seen]
    if not found:
        return MaterialMatch(text, None, 0.0, "unmatched")
    primary = {w.word for w in words if w.known and w.primary}
    position: dict[str, int] = {}
    for i, w in enumerate(words):
        position.setdefault(w.word, i)
    best = max(found, key=lambda p: (p.words <= primary, len(p.words), not p.generic,
                                     max(position[w] for w in p.words)))
    rivals = {p.name for p in found if p.name != best.name and not p.generic and not p.words <= best.words}
    matched = set().union(*(p.words for p in found))
    unknown = [w for w in words if w.word not in matched | v.ignore | v.generic]
    spelling = 1.0
    for w in words:
        if w.word in best.words:
            spelling *= w.ratio
    score = ((_GENERIC if best.generic else _SPECIFIC) * _PER_RIVAL ** len(rivals) * _PER_UNKNOWN ** len(unknown)
             * spelling)
    return MaterialMatch(text, best.name, round(score, 3), "spelling" if spelling < 1.0 else "words")


def suggest_materials(text: str, count: int = 3) -> tuple[str, ...]:
    """Up to `count` library keys nearest to `text`, best first: its match however weak, then the keys
    whose names or aliases are spelt most alike (none below a likeness of 0.7)."""
    match = match_material(text)
    v = _vocabulary()
    raw = _raw_words(text)
    if not raw:
        return (match.name,) if match.name else ()
    joined = "_".join(raw)
    long_raw = [r for r in raw if len(r) >= 4] or [""]  # short words are alike by accident ('thing' / 'tin')
    likeness: dict[str, float] = {}
    for p in v.phrases:
        long_words = [w for w in p.words if len(w) >= 4]
        per_word = sum(max(difflib.SequenceMatcher(None, w, r).ratio() for r in long_raw)
                       for w in long_words) / len(p.words)
        whole = difflib.SequenceMatcher(None, joined, p.text).ratio()
        likeness[p.name] = max(likeness.get(p.name, 0.0), per_word, whole)
    ranked = sorted((name for name, s in likeness.items() if s >= _SUGGEST_CUTOFF), key=lambda n: (-likeness[n], n))
    names = ([match.name] if match.name else []) + [n for n in ranked if n != match.name]
    return tuple(names[:count])


def _from_entry(name: str, entry: dict) -> MaterialRange:
    d, f = entry["density"], entry["friction"]
    fk = entry.get("friction_kinetic", [None, None, None])
    triple = lambda k: tuple(float(x) for x in entry[k]) if k in entry else None  # noqa: E731
    return MaterialRange(
        name, d[0], d[1], d[2], f[0], f[1], f[2], entry["source"],
        friction_kinetic=fk[0], friction_kinetic_low=fk[1], friction_kinetic_high=fk[2],
        structure=entry.get("structure", "solid"), solid_density=triple("solid_density"), wall_m=triple("wall_m"),
        category=entry.get("category", ""),
    )
