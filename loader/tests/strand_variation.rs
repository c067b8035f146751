//! Per-strand variation of a hair object's material: the documented forms parse, a varied
//! object adds its variants to the scene's materials, bad variations are errors naming the
//! object and the field.

use std::error::Error;
use std::path::Path;
use tress_core::Material;
use tress_loader::scene_desc::{build, parse, BuiltScene};

/// A scene of procedural hair with material `model` and the object's `variation` (RON).
fn scene(model: &str, variation: &str) -> String {
    format!(
        r#"(
            camera: (look_from: (0, 0, 4), look_at: (0, 0, 0)),
            film: (width: 8, height: 8, spp: 1, seed: 1),
            materials: {{ "hair": Hair({model}) }},
            objects: [Hair(source: Procedural(style: Ball, strands: 200, seed: 2),
                           material: "hair", {variation})],
            lights: [Sky()],
        )"#
    )
}

/// The scene `text` built as if read from `v.ron`; the error is its chain of causes as the
/// command line prints it.
fn build_text(text: &str) -> Result<BuiltScene, String> {
    let desc = parse(text).map_err(|e| e.to_string())?;
    build(&desc, Path::new("v.ron"), &Default::default()).map_err(|e| {
        let causes = std::iter::successors(Some(&e as &dyn Error), |&e| e.source());
        causes
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(": ")
    })
}

#[test]
fn the_documented_variation_forms_parse() {
    let source = include_str!("../../materials/src/strand_variation.rs");
    let start = source.find("/// ```ron\n/// (random").expect("the example");
    let block: Vec<&str> = source[start..]
        .lines()
        .skip(1)
        .take_while(|l| !l.contains("```"))
        .map(|l| l.trim_start_matches("///").trim())
        .collect();
    assert_eq!(block.len(), 4);
    for line in block {
        tress_loader::ron_options()
            .from_str::<tress_materials::strand_variation::StrandVariation>(line)
            .unwrap_or_else(|e| panic!("{line}: {e}"));
    }
}

#[test]
fn a_varied_object_adds_its_variants_to_the_materials() {
    let built = build_text(&scene(
        "Chiang(pigment: Melanin(eumelanin: 1.3))",
        "variation: Some(random: 0.5, seed: 3, variants: 6, \
         gradient: Some(tip: Scale(0.3), start: 0.6))",
    ))
    .unwrap();
    // The named material, then its 6 variants.
    assert_eq!(built.scene.materials.len(), 7);
    assert!(built
        .scene
        .materials
        .iter()
        .all(|m| matches!(m, Material::Hair(_))));
    assert!(
        built
            .summary
            .contains("objects[0]: 6 pigment variants (materials 1–6)"),
        "{}",
        built.summary
    );
    assert!(
        built.summary.contains("(materials 1–6)"),
        "{}",
        built.summary
    );
    // Without variation: one material, as before.
    let plain = build_text(&scene("Chiang()", "")).unwrap();
    assert_eq!(plain.scene.materials.len(), 1);
    // A variation that varies nothing: one variant, the material's own absorption.
    let one = build_text(&scene("Chiang()", "variation: Some()")).unwrap();
    assert_eq!(one.scene.materials.len(), 2);
    let (Material::Hair(a), Material::Hair(b)) = (&one.scene.materials[0], &one.scene.materials[1])
    else {
        panic!("hair materials expected")
    };
    use tress_materials::dual_scattering::fingerprint;
    assert_eq!(fingerprint(a.as_ref()), fingerprint(b.as_ref()));
}

#[test]
fn bad_variations_are_errors_naming_the_object_and_field() {
    let cases = [
        (
            "Chiang()",
            "variation: Some(random: 1.5)",
            "variation.random = 1.5",
        ),
        (
            "Chiang()",
            "variation: Some(random: NaN)",
            "variation.random = NaN",
        ),
        (
            "Chiang()",
            "variation: Some(variants: 0)",
            "variation.variants = 0",
        ),
        (
            "Chiang()",
            "variation: Some(variants: 100000)",
            "must lie in [1, 256]",
        ),
        (
            "Chiang()",
            "variation: Some(gradient: Some(tip: Scale(-1)))",
            "variation.gradient.tip = -1",
        ),
        (
            "Chiang()",
            "variation: Some(gradient: Some(tip: Scale(0.5), start: 1))",
            "variation.gradient.start = 1",
        ),
        (
            "Chiang()",
            "variation: Some(file_colors: true)",
            "variation.file_colors: procedural",
        ),
        (
            "Chiang()",
            "variation: Some(random_roughness: 1)",
            "variation.random_roughness = 1: must lie in [0, 1)",
        ),
        (
            "Chiang()",
            "variation: Some(darken_roots: Some(amount: -1))",
            "variation.darken_roots.amount = -1",
        ),
        (
            "Chiang()",
            "variation: Some(darken_roots: Some(amount: 1, length: 0))",
            "variation.darken_roots.length = 0: must lie in (0, 1]",
        ),
        (
            "LambertianFiber()",
            "variation: Some(random: 0.2)",
            "has no pigment to vary",
        ),
    ];
    for (model, variation, expect) in cases {
        let e = build_text(&scene(model, variation))
            .err()
            .unwrap_or_else(|| panic!("{variation}: accepted"));
        assert!(
            e.starts_with("v.ron: objects[0]: material 'hair': ") && e.contains(expect),
            "{variation}: {e}"
        );
    }
    // Misspelt fields are refused by the parser.
    for (typo, name) in [
        ("variation: Some(randm: 0.5)", "randm"),
        (
            "variation: Some(gradient: Some(tip: Scale(0.5), strat: 0.2))",
            "strat",
        ),
        (
            "variation: Some(gradient: Some(tip: Bleach(0.5)))",
            "Bleach",
        ),
        (
            "variation: Some(darken_roots: Some(amount: 1, lenght: 0.2))",
            "lenght",
        ),
    ] {
        let e = parse(&scene("Chiang()", typo))
            .expect_err("a parse error")
            .to_string();
        assert!(e.starts_with("6:") && e.contains(name), "{typo}: {e}");
    }
}
