//! Placeholders in scene files: `${name}` and `${name:-default}`, filled by `-D name=value`.

use crate::error::{Error, Result};
use std::collections::BTreeMap;

/// Values for a scene file's `${name}` placeholders, from `-D name=value` on the command line.
pub type Defines = BTreeMap<String, String>;

/// The `-D name=value` arguments as [`Defines`]: a name given twice is refused (the last
/// value was kept silently).
pub fn defines(args: &[(String, String)]) -> Result<Defines> {
    let mut defines = Defines::new();
    for (name, value) in args {
        if let Some(first) = defines.insert(name.clone(), value.clone()) {
            return Err(Error::DefinedTwice {
                name: name.clone(),
                first,
                second: value.clone(),
            });
        }
    }
    Ok(defines)
}

/// One `-D name=value` argument.
pub fn parse_define(arg: &str) -> std::result::Result<(String, String), String> {
    let (name, value) = arg
        .split_once('=')
        .ok_or_else(|| format!("'{arg}': write name=value"))?;
    if !is_placeholder_name(name) {
        return Err(format!(
            "'{name}': a name is a letter or _ followed by letters, digits or _"
        ));
    }
    if value.contains(['\n', '\r']) {
        return Err(format!("{name}: the value must be one line"));
    }
    Ok((name.to_owned(), value.to_owned()))
}

fn is_placeholder_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Replaces every `${name}` in a scene's text with `defines[name]`, and `${name:-default}`
/// with it or, when it is not defined, with `default` (Mitsuba's `$name` parameters, in shell
/// syntax, since `$` has no meaning in RON). Substitution is textual — it applies inside
/// comments too — so a placeholder may stand for a number, a string's contents or a whole
/// value: `spp: ${spp:-64}`, `File("${groom}.hair")`, `integrator: ${integrator:-DualMis()}`.
/// Errors (`line:column: message`): a placeholder with no value and no default, a malformed
/// one, and a define that the scene never uses (a misspelt name would otherwise be ignored).
pub fn substitute(text: &str, defines: &Defines) -> std::result::Result<String, String> {
    let mut out = String::with_capacity(text.len());
    let mut used = std::collections::BTreeSet::new();
    let mut rest = text;
    while let Some(at) = rest.find("${") {
        out.push_str(&rest[..at]);
        let offset = text.len() - rest.len() + at;
        let (line, col) = line_col(text, offset);
        let body = &rest[at + 2..];
        let end = body
            .find('}')
            .filter(|&e| !body[..e].contains('\n'))
            .ok_or_else(|| format!("{line}:{col}: '${{' without a closing '}}' on its line"))?;
        let (name, default) = match body[..end].split_once(":-") {
            Some((name, default)) => (name, Some(default)),
            None => (&body[..end], None),
        };
        if default.is_some_and(|d| d.contains("${")) {
            return Err(format!(
                "{line}:{col}: '${{{name}:-…}}': a default cannot hold another placeholder \
                 (nested defaults are not supported): write the value itself"
            ));
        }
        if !is_placeholder_name(name) {
            return Err(format!(
                "{line}:{col}: '${{{}}}': a placeholder is ${{name}} or ${{name:-default}}",
                &body[..end]
            ));
        }
        match (defines.get(name), default) {
            (Some(value), _) => {
                used.insert(name);
                out.push_str(value);
            }
            (None, Some(default)) => out.push_str(default),
            (None, None) => {
                return Err(format!(
                    "{line}:{col}: ${{{name}}} has no value: pass -D {name}=… or write \
                     ${{{name}:-default}}"
                ))
            }
        }
        rest = &body[end + 1..];
    }
    out.push_str(rest);
    if let Some(unused) = defines.keys().find(|k| !used.contains(k.as_str())) {
        return Err(format!(
            " -D {unused}: the scene has no ${{{unused}}} placeholder"
        ));
    }
    Ok(out)
}

/// 1-based line and column (in characters) of byte `offset` of `text`.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before[before.rfind('\n').map_or(0, |i| i + 1)..]
        .chars()
        .count()
        + 1;
    (line, col)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn defines(pairs: &[(&str, &str)]) -> Defines {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn placeholders_take_defines_then_defaults() {
        let text = "film: (spp: ${spp:-64}, seed: ${seed}),\n// ${spp:-}\nfile: \"${groom}.hair\"";
        let d = defines(&[("seed", "7"), ("groom", "a/b"), ("spp", "16")]);
        assert_eq!(
            substitute(text, &d).unwrap(),
            "film: (spp: 16, seed: 7),\n// 16\nfile: \"a/b.hair\""
        );
        let d = defines(&[("seed", "7"), ("groom", "x")]);
        assert!(substitute(text, &d)
            .unwrap()
            .starts_with("film: (spp: 64, seed: 7)"));
        // A default may be empty or hold a whole value; text without placeholders is unchanged.
        assert_eq!(substitute("${a:-}", &Defines::new()).unwrap(), "");
        assert_eq!(
            substitute("i: ${i:-Path(max_depth: 8)}", &Defines::new()).unwrap(),
            "i: Path(max_depth: 8)"
        );
        assert_eq!(substitute("a $b {c}", &Defines::new()).unwrap(), "a $b {c}");
    }

    #[test]
    fn placeholder_errors_say_where_and_what() {
        let err = |text: &str, d: &[(&str, &str)]| substitute(text, &defines(d)).unwrap_err();
        let e = err("(\n  film: (spp: ${spp}),", &[]);
        assert!(
            e.starts_with("2:15: ${spp} has no value: pass -D spp="),
            "{e}"
        );
        let e = err("x: ${spp", &[]);
        assert!(e.starts_with("1:4:") && e.contains("closing"), "{e}");
        let e = err("x: ${s p}", &[]);
        assert!(e.contains("${name}"), "{e}");
        let e = err("x: ${spp:-1}", &[("sp", "2")]);
        assert!(e.contains("-D sp: the scene has no ${sp}"), "{e}");
    }

    #[test]
    fn define_arguments_are_name_equals_value() {
        assert_eq!(
            parse_define("spp=64").unwrap(),
            ("spp".to_string(), "64".to_string())
        );
        assert_eq!(parse_define("x=a=b").unwrap().1, "a=b");
        assert!(parse_define("spp").unwrap_err().contains("name=value"));
        assert!(parse_define("1x=2").is_err());
        assert!(parse_define("x=a\nb").is_err());
    }
}
