"""Free-text material hints: descriptions as written on product pages, in catalogues and lab notes."""

from __future__ import annotations

import pytest

from assets.materials import (
    MATCH_THRESHOLD, MaterialMatch, find_material, match_material, material_names, material_range, suggest_materials,
)

# (hint as written, expected library key), grouped by where such words are found.
DESCRIPTIONS = [
    # furniture and homeware product pages
    ("Solid beech wood", "wood_beech"),
    ("Wood, beech", "wood_beech"),
    ("wooden beech", "wood_beech"),
    ("Beech wood, oiled finish", "wood_beech"),
    ("Oak veneer", "wood_oak"),
    ("solid oak, natural oil", "wood_oak"),
    ("White oak hardwood", "wood_oak"),
    ("Solid pine", "wood_pine"),
    ("pine wood, untreated", "wood_pine"),
    ("Spruce timber", "wood_pine"),
    ("Walnut", "wood_maple"),
    ("Hard maple", "wood_maple"),
    ("Birch plywood", "plywood"),
    ("Baltic birch plywood, 18 mm", "plywood"),
    ("Painted MDF", "mdf"),
    ("MDF with oak veneer", "mdf"),
    ("High-gloss lacquered MDF", "mdf"),
    ("Melamine-faced chipboard", "particleboard"),
    ("Particle board", "particleboard"),
    ("OSB", "particleboard"),
    ("Bamboo", "wood_oak"),
    ("Cork board", "cork"),
    ("Tempered glass", "glass"),
    ("Borosilicate glass", "glass"),
    ("Glass jar", "glass_bottle"),
    ("Porcelain, dishwasher safe", "porcelain"),
    ("Bone china", "porcelain"),
    ("Stoneware mug", "ceramic_earthenware"),
    ("Terracotta", "ceramic_earthenware"),
    ("Marble", "stone_granite"),
    ("Genuine leather", "leather"),
    ("100% cotton", "fabric"),
    ("Wool felt", "fabric"),
    ("Paraffin wax candle", "paraffin_wax"),
    # tool and hardware catalogues
    ("Chrome vanadium steel", "steel"),
    ("Forged steel", "steel"),
    ("Drop-forged carbon steel", "steel"),
    ("Powder-coated steel", "steel"),
    ("Galvanized steel", "steel"),
    ("Hardened tool steel", "steel"),
    ("Stainless steel 304", "stainless_steel"),
    ("AISI 316 stainless", "stainless_steel"),
    ("Inox", "stainless_steel"),
    ("Sheet metal", "sheet_steel"),
    ("Cast iron", "cast_iron"),
    ("Anodized aluminium", "aluminium"),
    ("Anodised aluminum", "aluminium"),
    ("Aluminium alloy 6061-T6", "aluminium"),
    ("Die-cast aluminum", "aluminium"),
    ("Solid brass", "brass"),
    ("Bronze", "brass"),
    ("Copper", "copper"),
    ("Rubber grip", "rubber"),
    ("Neoprene", "rubber"),
    ("Silicone", "silicone_rubber"),
    ("PTFE (Teflon)", "ptfe"),
    ("Nylon 6", "nylon"),
    ("Polyamide PA12", "nylon"),
    # 3D-printing notes
    ("PLA, 20% infill", "pla_printed"),
    ("3D printed PLA", "pla_printed"),
    ("PLA+ printed, 15% gyroid infill", "pla_printed"),
    ("Solid PLA", "pla_solid"),
    ("PETG print", "petg_printed"),
    ("printed PETG, 3 walls", "petg_printed"),
    ("ABS, FDM printed", "abs_printed"),
    ("TPU 95A", "tpu_printed"),
    # packaging
    ("Corrugated cardboard box", "cardboard_box"),
    ("Shipping box", "cardboard_box"),
    ("Cardboard", "cardboard"),
    ("EPS foam", "foam_polystyrene"),
    ("Styrofoam block", "foam_polystyrene"),
    ("Expanded polystyrene", "foam_polystyrene"),
    ("XPS insulation board", "foam_polystyrene"),
    ("PE foam", "foam_polystyrene"),
    ("PU foam", "foam_polyurethane"),
    ("Polyurethane foam", "foam_polyurethane"),
    ("Memory foam", "foam_polyurethane"),
    ("EVA foam", "foam_eva"),
    ("PET bottle", "petg"),
    ("HDPE", "hdpe"),
    ("Low-density polyethylene", "ldpe"),
    ("PP plastic", "polypropylene"),
    ("Polypropylene (PP)", "polypropylene"),
    ("Stack of paper", "paper_stack"),
    # lab notes
    ("alu block", "aluminium"),
    ("POM (Delrin)", "acetal"),
    ("acetal rod", "acetal"),
    ("Plexiglas", "acrylic"),
    ("acrylic sheet, 5 mm", "acrylic"),
    ("perspex", "acrylic"),
    ("polycarbonate", "polycarbonate"),
    ("PVC pipe", "pvc_rigid"),
    ("ABS plastic", "abs"),
    ("made of steel", "steel"),
    ("approx. 2.7 g/cm3 aluminium", "aluminium"),
    ("granite", "stone_granite"),
    ("apples", "apple"),
    ("potatoes", "potato"),
    ("oranges", "citrus"),
    ("a loaf of bread", "bread"),
    ("egg", "egg"),
    ("full water bottle", "water_filled"),
    # more of the same, written after the matcher, to check that it was not fitted to the lines above
    ("Beechwood", "wood_beech"),
    ("Pinewood frame", "wood_pine"),
    ("Kiln-dried pine", "wood_pine"),
    ("Oak-effect laminate", "particleboard"),
    ("Hardwood plywood", "plywood"),
    ("Balsa sheet", "wood_balsa"),
    ("Cork coaster", "cork"),
    ("Kraft paper roll", "paper_stack"),
    ("Aluminium foil", "aluminium"),
    ("Extruded aluminium profile", "aluminium"),
    ("Enamelled cast iron", "cast_iron"),
    ("Chrome-plated brass", "brass"),
    ("Brass fitting", "brass"),
    ("Copper pipe", "copper"),
    ("Zinc-plated steel", "steel"),
    ("Mild steel flat bar", "steel"),
    ("Tin can", "sheet_steel"),
    ("Nitrile rubber", "rubber"),
    ("Natural latex", "rubber"),
    ("Food-grade silicone", "silicone_rubber"),
    ("UHMW-PE", "hdpe"),
    ("LDPE film", "ldpe"),
    ("Acrylic (PMMA)", "acrylic"),
    ("Polycarbonate (Lexan)", "polycarbonate"),
    ("HIPS", "polystyrene"),
    ("PVC-U", "pvc_rigid"),
    ("Nylon 66 (PA66)", "nylon"),
    ("ASA printed", "abs_printed"),
    ("Corrugated plastic sheet", "polypropylene"),
    ("Polyethylene foam", "foam_polystyrene"),
    ("Foam rubber", "foam_polyurethane"),
    ("Styrofoam cup", "foam_polystyrene"),
    ("Polystyrene packaging foam", "foam_polystyrene"),
    ("Faux leather", "leather"),
    ("Leatherette", "leather"),
    ("Canvas bag", "fabric"),
    ("Cotton towel", "fabric"),
    ("Beeswax block", "paraffin_wax"),
    ("Glass bottle (empty)", "glass_bottle"),
    ("Ceramic plate", "porcelain"),
    ("Earthenware pot", "ceramic_earthenware"),
    ("Granite countertop offcut", "stone_granite"),
    ("Lemons", "citrus"),
    ("Sourdough bread", "bread"),
    ("Hard-boiled egg", "egg"),
    # common misspellings
    ("alumninium", "aluminium"),
    ("aluminum", "aluminium"),
    ("stainles steel", "stainless_steel"),
    ("polycarbonat", "polycarbonate"),
    ("plywod", "plywood"),
    ("polypropylen", "polypropylene"),
    ("porcelan", "porcelain"),
    ("cardbord", "cardboard"),
]

NOT_MATERIALS = ["my favourite thing", "unknown", "", "asdf", "n/a", "TBD", "see photo", "coated", "tiny figurine", "?"]


def test_descriptions_resolve_to_the_expected_entry():
    """At least 95 % of the table resolves, as find_material, to the expected key; the misses are printed."""
    assert len(DESCRIPTIONS) >= 60
    assert {key for _, key in DESCRIPTIONS} <= set(material_names())
    misses = []
    for text, key in DESCRIPTIONS:
        found = find_material(text)
        if found is None or found.name != key:
            misses.append((text, key, match_material(text)))
    for miss in misses:
        print("miss:", *miss)
    hit_rate = 1 - len(misses) / len(DESCRIPTIONS)
    print(f"hit rate {hit_rate:.1%} over {len(DESCRIPTIONS)} descriptions")
    assert hit_rate >= 0.95


@pytest.mark.parametrize("text", [t for t, _ in DESCRIPTIONS] + NOT_MATERIALS)
def test_every_description_is_handled(text):
    """No hint raises; the match keeps the text as written and a score in 0..1."""
    m = match_material(text)
    assert isinstance(m, MaterialMatch) and m.text == text
    assert 0.0 <= m.score <= 1.0 and m.how
    assert (m.name is None) == (m.how == "unmatched")
    suggest_materials(text)


def test_keys_and_aliases_are_sure():
    assert match_material("wood_beech") == MaterialMatch("wood_beech", "wood_beech", 1.0, "exact")
    assert match_material("Delrin") == MaterialMatch("Delrin", "acetal", 1.0, "synonym")
    m = match_material("beech wood")
    assert m.name == "wood_beech" and MATCH_THRESHOLD <= m.score < 1.0 and m.how == "words"
    assert match_material("stainles steel").how == "spelling"


@pytest.mark.parametrize("text", NOT_MATERIALS)
def test_text_naming_no_material_is_unmatched(text):
    m = match_material(text)
    assert (m.name, m.score, m.how) == (None, 0.0, "unmatched")


def test_unknown_keeps_the_wide_range():
    assert find_material("unknown") == material_range(None)
    assert find_material("Unknown").name == "unknown"


def test_weak_guesses_do_not_pass_as_explicit_names():
    """A class word amid unknown words is a guess: match_material reports it, find_material refuses it."""
    m = match_material("wooden toy car")
    assert m.name == "wood_pine" and m.score < MATCH_THRESHOLD
    assert find_material("wooden toy car") is None
    assert find_material("plastic") is None and find_material("metal") is None


@pytest.mark.parametrize(("text", "key"), [
    ("almnm", "aluminium"), ("stanless", "stainless_steel"), ("polycarbnt", "polycarbonate"),
    ("alumnum foil", "aluminium"), ("plywud", "plywood"),
])
def test_suggestions_for_misspelt_names_contain_the_entry(text, key):
    assert key in suggest_materials(text)
    assert len(suggest_materials(text, count=2)) <= 2


def test_unknown_name_error_is_one_line_naming_the_nearest():
    with pytest.raises(ValueError) as err:
        material_range("almnm")
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("unknown material 'almnm'; nearest: aluminium")
    assert "assets/materials.json" in message
    nothing_near = r"^unknown material 'asdf'; choose one of the keys in assets/materials\.json$"
    with pytest.raises(ValueError, match=nothing_near):
        material_range("asdf")


def test_matching_is_deterministic():
    texts = [t for t, _ in DESCRIPTIONS] + NOT_MATERIALS
    assert [match_material(t) for t in texts] == [match_material(t) for t in texts]
    assert [suggest_materials(t) for t in texts] == [suggest_materials(t) for t in texts]
