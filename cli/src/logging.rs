//! `--log-format`: how a command reports. The default is for people (progress bars and
//! summaries on stderr, tables on stdout); `json` is for scripts and farms: no progress bars or
//! readable summaries, and as the last line on stdout exactly one JSON object (after the text
//! that is a command's product, such as `tress farm`'s job list),
//!
//! ```json
//! {"command":"diff","flip":{"mean":0.046,…},"mse":{"all":0.0028,…},…,"status":"ok"}
//! ```
//!
//! with `status` `ok`, `error` (and `error`: the message) or `interrupted`, plus whatever the
//! command recorded with [`record`] before it ended.

use serde::Serialize;
use serde_json::{Map, Value};
use std::sync::{Mutex, OnceLock};

/// How commands report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    /// Progress bars and readable summaries.
    #[default]
    Human,
    /// No progress bars or readable summaries; one JSON summary line ends stdout.
    Json,
}

static FORMAT: OnceLock<LogFormat> = OnceLock::new();
static FIELDS: Mutex<Option<Map<String, Value>>> = Mutex::new(None);

/// Sets the format for the whole run (the first call wins).
pub fn set_format(format: LogFormat) {
    let _ = FORMAT.set(format);
}

/// Whether the run reports in JSON.
pub fn json() -> bool {
    FORMAT.get() == Some(&LogFormat::Json)
}

/// Adds `key` to the command's JSON summary (replacing an earlier value). Values that cannot be
/// represented in JSON (non-finite floats) are written as `null`.
pub fn record(key: &str, value: impl Serialize) {
    let value = serde_json::to_value(value).unwrap_or(Value::Null);
    let mut fields = FIELDS.lock().unwrap_or_else(|e| e.into_inner());
    fields
        .get_or_insert_with(Map::new)
        .insert(key.to_string(), value);
}

/// How a command ended.
pub enum Outcome<'a> {
    Ok,
    Interrupted,
    Error(&'a anyhow::Error),
}

/// The summary line of `command`: its status and the recorded fields (keys in sorted order).
pub fn summary_line(command: &str, outcome: Outcome) -> String {
    let mut line = Map::new();
    line.insert("command".into(), command.into());
    let status = match outcome {
        Outcome::Ok => "ok",
        Outcome::Interrupted => "interrupted",
        Outcome::Error(_) => "error",
    };
    line.insert("status".into(), status.into());
    if let Outcome::Error(e) = outcome {
        line.insert("error".into(), format!("{e:#}").into());
    }
    let fields = FIELDS.lock().unwrap_or_else(|e| e.into_inner()).take();
    for (k, v) in fields.unwrap_or_default() {
        // The status is the runner's to say.
        if !line.contains_key(&k) {
            line.insert(k, v);
        }
    }
    Value::Object(line).to_string()
}

/// Prints the summary line of `command` on stdout when the run reports in JSON.
pub fn finish(command: &str, outcome: Outcome) {
    if json() {
        println!("{}", summary_line(command, outcome));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_line_is_one_json_object_with_the_recorded_fields() {
        record("spp", 64u32);
        record("time_s", 1.5f64);
        record("outputs", ["a.exr", "a.png"]);
        record("not_finite", f64::NAN);
        record("spp", 128u32);
        let line = summary_line("render", Outcome::Ok);
        assert!(!line.contains('\n'));
        let v: Value = serde_json::from_str(&line).unwrap();
        assert_eq!(v["command"], "render");
        assert_eq!(v["status"], "ok");
        assert_eq!(v["spp"], 128);
        assert_eq!(v["time_s"], 1.5);
        assert_eq!(v["outputs"][1], "a.png");
        assert!(v["not_finite"].is_null());
        // Taken: the next command starts empty.
        let e = anyhow::anyhow!("inner").context("outer");
        let v: Value = serde_json::from_str(&summary_line("diff", Outcome::Error(&e))).unwrap();
        assert_eq!(v["status"], "error");
        assert_eq!(v["error"], "outer: inner");
        assert!(v.get("spp").is_none());
    }
}
