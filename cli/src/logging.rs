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
//! command recorded with [`Log::record`] before it ended. A [`Log`] belongs to one run of one
//! command: `main` makes it and hands it to the command.

use serde::Serialize;
use serde_json::{Map, Value};

/// How commands report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    /// Progress bars and readable summaries.
    #[default]
    Human,
    /// No progress bars or readable summaries; one JSON summary line ends stdout.
    Json,
}

/// How a command ended.
pub enum Outcome<'a> {
    Ok,
    Interrupted,
    Error(&'a anyhow::Error),
}

/// The report of one command's run: its format and the fields of its JSON summary.
#[derive(Debug)]
pub struct Log {
    format: LogFormat,
    fields: Map<String, Value>,
}

impl Log {
    /// An empty report in `format`.
    pub fn new(format: LogFormat) -> Log {
        Log {
            format,
            fields: Map::new(),
        }
    }

    /// Whether the run reports in JSON.
    pub fn json(&self) -> bool {
        self.format == LogFormat::Json
    }

    /// Adds `key` to the command's JSON summary (replacing an earlier value). Values that
    /// cannot be represented in JSON (non-finite floats) are written as `null`.
    pub fn record(&mut self, key: &str, value: impl Serialize) {
        let value = serde_json::to_value(value).unwrap_or(Value::Null);
        self.fields.insert(key.to_string(), value);
    }

    /// The summary line of `command`: its status and the recorded fields (keys in sorted order).
    pub fn summary_line(&self, command: &str, outcome: Outcome) -> String {
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
        for (k, v) in &self.fields {
            // The status is the runner's to say.
            if !line.contains_key(k) {
                line.insert(k.clone(), v.clone());
            }
        }
        Value::Object(line).to_string()
    }

    /// Prints the summary line of `command` on stdout when the run reports in JSON.
    pub fn finish(&self, command: &str, outcome: Outcome) {
        if self.json() {
            println!("{}", self.summary_line(command, outcome));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_line_is_one_json_object_with_the_recorded_fields() {
        let mut log = Log::new(LogFormat::Json);
        log.record("spp", 64u32);
        log.record("time_s", 1.5f64);
        log.record("outputs", ["a.exr", "a.png"]);
        log.record("not_finite", f64::NAN);
        log.record("spp", 128u32);
        log.record("status", "recorded");
        let line = log.summary_line("render", Outcome::Ok);
        assert!(!line.contains('\n'));
        let v: Value = serde_json::from_str(&line).unwrap();
        assert_eq!(v["command"], "render");
        assert_eq!(v["status"], "ok");
        assert_eq!(v["spp"], 128);
        assert_eq!(v["time_s"], 1.5);
        assert_eq!(v["outputs"][1], "a.png");
        assert!(v["not_finite"].is_null());
        // Each run has its own log: another command's starts empty.
        let e = anyhow::anyhow!("inner").context("outer");
        let other = Log::new(LogFormat::Json);
        let v: Value =
            serde_json::from_str(&other.summary_line("diff", Outcome::Error(&e))).unwrap();
        assert_eq!(v["status"], "error");
        assert_eq!(v["error"], "outer: inner");
        assert!(v.get("spp").is_none());
    }
}
