//! The scene types as scene files write them: the documented forms parse, misspelt fields are
//! refused in every variant.

use serde::de::DeserializeOwned;

/// The ```` ```ron ```` blocks of a source file's doc comments.
fn ron_blocks(source: &str) -> Vec<Vec<String>> {
    let mut blocks = Vec::new();
    let mut current: Option<Vec<String>> = None;
    for line in source.lines() {
        let Some(doc) = line.trim_start().strip_prefix("///") else {
            continue;
        };
        let doc = doc.strip_prefix(' ').unwrap_or(doc);
        match (&mut current, doc.trim()) {
            (None, "```ron") => current = Some(Vec::new()),
            (Some(_), "```") => blocks.extend(current.take()),
            (Some(block), _) => block.push(doc.split("//").next().unwrap().to_owned()),
            (None, _) => {}
        }
    }
    blocks
}

#[test]
fn the_documented_hair_source_and_option_forms_parse_as_scene_files_write_them() {
    let sources = ron_blocks(include_str!("../../groom/src/source.rs"));
    let options = ron_blocks(include_str!("../../accel/src/options.rs"));
    assert_eq!(
        (sources.len(), options.len()),
        (1, 1),
        "{sources:?} {options:?}"
    );
    for line in sources[0].iter().filter(|l| !l.trim().is_empty()) {
        tress_loader::ron_options()
            .from_str::<tress_groom::HairSource>(line)
            .unwrap_or_else(|e| panic!("{line}: {e}"));
    }
    let options = options[0].join("\n");
    let parsed: tress_accel::HairOptions = tress_loader::ron_options()
        .from_str(&options)
        .unwrap_or_else(|e| panic!("{options}: {e}"));
    assert_eq!(parsed.curve, tress_accel::CurveShape::Round);
}

/// The variant names of `T`, from the error a variant that does not exist gives.
fn variants<T: DeserializeOwned + std::fmt::Debug>() -> Vec<String> {
    let err = tress_loader::ron_options()
        .from_str::<T>("NoSuchVariant()")
        .unwrap_err()
        .to_string();
    let expected = err.rsplit("expected").next().unwrap_or_default();
    let names: Vec<String> = expected
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|n| *n != "NoSuchVariant" && n.chars().next().is_some_and(char::is_uppercase))
        .map(str::to_string)
        .collect();
    assert!(names.len() >= 2, "cannot read the variants from: {err}");
    names
}

/// Every variant of every enum a scene is written with refuses a misspelt field (the list of
/// variants comes from serde, so a new variant is covered automatically).
fn refuses_typos<T: DeserializeOwned + std::fmt::Debug>(what: &str) {
    for v in variants::<T>() {
        let text = format!("{v}(zz_typo: 1)");
        match tress_loader::ron_options().from_str::<T>(&text) {
            Ok(parsed) => panic!("{what}: `{text}` was accepted as {parsed:?}"),
            // Struct variants name the field; tuple variants refuse the syntax. A missing-field
            // error would mean the misspelt field was skipped silently.
            Err(e) => assert!(
                e.to_string().contains("zz_typo") || !e.to_string().contains("field"),
                "{what}: `{text}` failed without naming the field: {e}"
            ),
        }
    }
}

#[test]
fn misspelt_fields_are_refused_in_every_variant() {
    refuses_typos::<tress_loader::materials::MaterialDesc>("material");
    refuses_typos::<tress_loader::lights::LightDesc>("light");
    refuses_typos::<tress_loader::geometry::ObjectDesc>("object");
    refuses_typos::<tress_loader::integrators::IntegratorDesc>("integrator");
    refuses_typos::<tress_materials::HairModel>("hair model");
    refuses_typos::<tress_materials::pigment::Pigment>("pigment");
    refuses_typos::<tress_groom::HairSource>("hair source");
    refuses_typos::<tress_groom::HairStyle>("hair style");
}
