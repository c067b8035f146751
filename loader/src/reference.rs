//! The scene-file reference (`docs/src/reference/scene-file.md`, a chapter of the book), generated from the serde types themselves:
//! their JSON schema (schemars) carries every field, its type, its default and the doc comment
//! that states its unit and range, so the reference cannot drift from what the parser accepts
//! (a test compares the committed file with a fresh one).

use serde_json::{Map, Value};
use std::fmt::Write as _;

/// The reference as Markdown.
pub fn scene_reference() -> String {
    let schema = serde_json::to_value(schemars::schema_for!(crate::scene_desc::SceneDesc))
        .expect("a schema is JSON");
    let empty = Map::new();
    let defs = schema["$defs"].as_object().unwrap_or(&empty);
    let mut out = String::from(
        "# Scene file reference\n\n\
         <!-- Generated from the scene types by `tress_loader::reference`; do not edit. After \
         changing a scene type, regenerate it with \
         `TRESS_BLESS=1 cargo test --release -p tress-loader --lib reference`. -->\n\n\
         Scene files are [RON](https://github.com/ron-rs/ron). A struct is written \
         `(field: value, …)`; an enum is written `Variant(field: value, …)`, or `Variant` when \
         it has no fields; an optional value is `Some(value)` or `None`; a list is \
         `[a, b, …]`; a vector `(x, y, z)`. Fields with a default may be left out; every other \
         field is required, and unknown fields are errors. Paths are relative to the scene \
         file's folder. Placeholders `${name}` and `${name:-default}` are filled by `-D \
         name=value` on the command line (the book's chapter \"Scenes\").\n\n",
    );
    section(&mut out, "Scene", &schema, defs);
    for (name, def) in defs {
        section(&mut out, name, def, defs);
    }
    out
}

/// One type: its description, then its fields (a struct) or its variants (an enum).
fn section(out: &mut String, name: &str, def: &Value, defs: &Map<String, Value>) {
    let _ = writeln!(out, "## {name}\n");
    if let Some(d) = def["description"].as_str() {
        let _ = writeln!(out, "{}\n", paragraphs(d, defs));
    }
    if let Some(fields) = def["properties"].as_object() {
        fields_table(out, fields, required(def), defs);
    } else if let Some(variants) = def["oneOf"].as_array() {
        for v in variants {
            variant(out, v, defs);
        }
        out.push('\n');
    }
}

fn required(def: &Value) -> Vec<&str> {
    def["required"]
        .as_array()
        .map(|r| r.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default()
}

fn fields_table(
    out: &mut String,
    fields: &Map<String, Value>,
    required: Vec<&str>,
    defs: &Map<String, Value>,
) {
    out.push_str("| field | type | default | meaning |\n|---|---|---|---|\n");
    for (field, f) in fields {
        let default = match f.get("default") {
            Some(d) => format!("`{}`", ron_value(d)),
            None if required.contains(&field.as_str()) => "required".into(),
            None => "–".into(),
        };
        let _ = writeln!(
            out,
            "| `{field}` | {} | {default} | {} |",
            type_name(f, defs),
            prose(f["description"].as_str().unwrap_or(""), defs).replace('|', "\\|")
        );
    }
    out.push('\n');
}

/// One variant of an externally tagged enum: a unit variant (a string), or a one-key object
/// whose value is the variant's content (fields, a newtype or a referenced type).
fn variant(out: &mut String, v: &Value, defs: &Map<String, Value>) {
    let description = prose(v["description"].as_str().unwrap_or(""), defs);
    if let Some(name) = v["const"].as_str() {
        let _ = writeln!(out, "- `{name}`: {description}");
        return;
    }
    let Some((name, content)) = v["properties"].as_object().and_then(|p| p.iter().next()) else {
        return;
    };
    if let Some(fields) = content["properties"].as_object() {
        // A heading after a list item needs a blank line before it.
        if !out.ends_with("\n\n") {
            out.push('\n');
        }
        let _ = writeln!(out, "### {name}(…)\n\n{description}\n");
        fields_table(out, fields, required(content), defs);
    } else if content.get("properties").is_none() && content["type"] == "object" {
        let _ = writeln!(out, "- `{name}()`: {description}");
    } else {
        let _ = writeln!(
            out,
            "- `{name}(…)` with {}: {description}",
            type_name(content, defs)
        );
    }
}

/// The type of a schema, as a scene file writes it.
fn type_name(s: &Value, defs: &Map<String, Value>) -> String {
    if let Some(r) = s["$ref"].as_str() {
        let name = r.rsplit('/').next().unwrap_or(r);
        return link(name, defs);
    }
    if let Some(any) = s["anyOf"].as_array() {
        let inner: Vec<_> = any.iter().filter(|a| a["type"] != "null").collect();
        if inner.len() == 1 && inner.len() < any.len() {
            return format!("`Option` of {}", type_name(inner[0], defs));
        }
    }
    let types: Vec<&str> = match &s["type"] {
        Value::String(t) => vec![t.as_str()],
        Value::Array(t) => t.iter().filter_map(Value::as_str).collect(),
        _ => Vec::new(),
    };
    let optional = types.contains(&"null");
    let base = match types.iter().find(|&&t| t != "null").copied() {
        Some("number") => "number".to_owned(),
        Some("integer") => match s["format"].as_str() {
            Some(f @ ("uint8" | "uint16" | "uint32" | "uint64")) => {
                format!("integer ≥ 0 ({})", f.replace("uint", "u"))
            }
            _ => "integer".to_owned(),
        },
        Some("boolean") => "`true` / `false`".to_owned(),
        Some("string") => "string".to_owned(),
        Some("array") => match (s["prefixItems"].as_array(), s["minItems"].as_u64()) {
            (Some(items), _) if items.len() == 3 => "`(x, y, z)`".to_owned(),
            (_, Some(3)) if s["maxItems"] == 3 && s["items"]["type"] == "number" => {
                "`(x, y, z)`".to_owned()
            }
            (_, Some(n)) if s["maxItems"].as_u64() == Some(n) => {
                format!("{n} × {}", type_name(&s["items"], defs))
            }
            _ => format!("list of {}", type_name(&s["items"], defs)),
        },
        Some("object") => match s.get("additionalProperties") {
            Some(v @ Value::Object(_)) => format!("map from name to {}", type_name(v, defs)),
            _ => "struct".to_owned(),
        },
        Some(other) => other.to_owned(),
        None => "value".to_owned(),
    };
    if optional {
        format!("`Option` of {base}")
    } else {
        base
    }
}

fn link(name: &str, defs: &Map<String, Value>) -> String {
    if defs.contains_key(name) {
        format!("[`{name}`](#{})", name.to_lowercase())
    } else {
        format!("`{name}`")
    }
}

/// A type's doc comment as Markdown paragraphs: its ```` ``` ```` examples kept as code
/// blocks, the prose between them as for [`prose`].
fn paragraphs(doc: &str, defs: &Map<String, Value>) -> String {
    doc.split("```")
        .enumerate()
        .map(|(i, part)| {
            if i % 2 == 1 {
                // A fence: its language tag on the first line, then the code as written.
                let (lang, code) = part.split_once('\n').unwrap_or((part, ""));
                format!("\n\n```{}\n{}\n```\n\n", lang.trim(), code.trim_end())
            } else {
                prose(part, defs)
            }
        })
        .collect::<String>()
        .trim()
        .to_owned()
}

/// A doc comment as one line of Markdown: rustdoc links turned into plain code or links to
/// the types of this reference.
fn prose(doc: &str, defs: &Map<String, Value>) -> String {
    let text = doc.split_whitespace().collect::<Vec<_>>().join(" ");
    let mut out = String::with_capacity(text.len());
    let mut rest = text.as_str();
    while let Some(start) = rest.find("[`") {
        out.push_str(&rest[..start]);
        let after = &rest[start + 2..];
        let Some(end) = after.find("`]") else {
            out.push_str(&rest[start..]);
            return out;
        };
        let name = &after[..end];
        let mut tail = &after[end + 2..];
        // `[`X`](path)`: the path is for rustdoc only.
        if tail.starts_with('(') {
            if let Some(close) = tail.find(')') {
                tail = &tail[close + 1..];
            }
        }
        let short = name.rsplit("::").next().unwrap_or(name);
        out.push_str(&link(short, defs));
        rest = tail;
    }
    out.push_str(rest);
    out
}

/// A default value in RON syntax: floats at f32 precision, lists of three as tuples, a
/// one-key object as an enum variant.
fn ron_value(v: &Value) -> String {
    match v {
        Value::Null => "None".into(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => match (n.as_u64(), n.as_i64(), n.as_f64()) {
            (Some(u), _, _) => u.to_string(),
            (_, Some(i), _) => i.to_string(),
            (_, _, Some(f)) => format!("{:?}", f as f32),
            _ => n.to_string(),
        },
        // A capitalised identifier is a unit variant (`FiberMedium`); anything else is text.
        Value::String(s) if is_variant(s) && s.chars().all(|c| c.is_ascii_alphanumeric()) => {
            s.clone()
        }
        Value::String(s) => format!("{s:?}"),
        Value::Array(items) => {
            let inner: Vec<_> = items.iter().map(ron_value).collect();
            if items.len() == 3 && items.iter().all(Value::is_number) {
                format!("({})", inner.join(", "))
            } else {
                format!("[{}]", inner.join(", "))
            }
        }
        Value::Object(map) => {
            let fields = |m: &Map<String, Value>| {
                m.iter()
                    .map(|(k, v)| format!("{k}: {}", ron_value(v)))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            match map.iter().next() {
                Some((variant, content)) if map.len() == 1 && is_variant(variant) => {
                    let inner = match content {
                        Value::Object(inner) => fields(inner),
                        // A newtype variant of a tuple: `Euler(0.0, 90.0, 0.0)`.
                        Value::Array(items) => {
                            items.iter().map(ron_value).collect::<Vec<_>>().join(", ")
                        }
                        other => ron_value(other),
                    };
                    format!("{variant}({inner})")
                }
                _ => format!("({})", fields(map)),
            }
        }
    }
}

/// Enum variants are capitalised; struct fields are not.
fn is_variant(key: &str) -> bool {
    key.starts_with(|c: char| c.is_ascii_uppercase())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The committed reference is what the types generate; `TRESS_BLESS=1` rewrites it.
    #[test]
    fn the_committed_scene_reference_is_current() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../docs/src/reference/scene-file.md");
        let fresh = scene_reference();
        if std::env::var_os("TRESS_BLESS").is_some() {
            std::fs::write(&path, &fresh).unwrap();
        }
        let committed = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            committed == fresh,
            "{} is out of date: regenerate it with \
             `TRESS_BLESS=1 cargo test --release -p tress-loader --lib reference`",
            path.display()
        );
    }

    /// Every field of every scene type is documented, and the reference names them all.
    #[test]
    fn every_scene_field_is_documented() {
        let schema =
            serde_json::to_value(schemars::schema_for!(crate::scene_desc::SceneDesc)).unwrap();
        let reference = scene_reference();
        let mut undocumented = Vec::new();
        let mut check = |owner: &str, fields: &Map<String, Value>| {
            for (name, f) in fields {
                if f["description"].as_str().is_none_or(str::is_empty) {
                    undocumented.push(format!("{owner}.{name}"));
                }
                assert!(
                    reference.contains(&format!("| `{name}` |")),
                    "{owner}.{name}"
                );
            }
        };
        check("Scene", schema["properties"].as_object().unwrap());
        for (name, def) in schema["$defs"].as_object().unwrap() {
            if let Some(fields) = def["properties"].as_object() {
                check(name, fields);
            }
            for v in def["oneOf"].as_array().into_iter().flatten() {
                for (variant, content) in v["properties"].as_object().into_iter().flatten() {
                    if let Some(fields) = content["properties"].as_object() {
                        check(&format!("{name}::{variant}"), fields);
                    }
                }
            }
        }
        assert!(undocumented.is_empty(), "undocumented: {undocumented:?}");
    }

    #[test]
    fn defaults_read_as_ron() {
        let v: Value = serde_json::json!({"Path": {"max_depth": 100, "rr_depth": 5}});
        assert_eq!(ron_value(&v), "Path(max_depth: 100, rr_depth: 5)");
        assert_eq!(
            ron_value(&serde_json::json!([0.800000011920929, 1.0, 0])),
            "(0.8, 1.0, 0)"
        );
        assert_eq!(ron_value(&serde_json::json!(null)), "None");
        assert_eq!(ron_value(&serde_json::json!({"a": 1})), "(a: 1)");
        assert_eq!(ron_value(&serde_json::json!({"m": "Paper"})), "(m: Paper)");
        assert_eq!(
            ron_value(&serde_json::json!({"Euler": [0.0, 90.0, 0.0]})),
            "Euler(0.0, 90.0, 0.0)"
        );
        assert_eq!(ron_value(&serde_json::json!("a.hair")), "\"a.hair\"");
    }
}
