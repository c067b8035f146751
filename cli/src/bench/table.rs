//! The bench table: rows, text and CSV.

use std::fmt::Write as _;
use tress_study::cost::Cost;

/// The table's columns, in order.
pub const COLUMNS: [&str; 7] = [
    "model", "section", "metric", "threads", "value", "unit", "note",
];

/// One measurement.
pub(super) struct Row {
    pub(super) model: String,
    pub(super) section: &'static str,
    pub(super) metric: String,
    pub(super) threads: Option<usize>,
    pub(super) value: Option<f64>,
    pub(super) unit: &'static str,
    pub(super) note: String,
}

#[derive(Default)]
pub(super) struct Table {
    pub(super) rows: Vec<Row>,
}

impl Table {
    /// A row of `section` for `model` (`at` = (model, section)).
    pub(super) fn push(
        &mut self,
        at: (&str, &'static str),
        metric: impl Into<String>,
        threads: Option<usize>,
        value: f64,
        unit: &'static str,
        note: impl Into<String>,
    ) {
        let (model, section) = at;
        self.rows.push(Row {
            model: model.to_string(),
            section,
            metric: metric.into(),
            threads,
            value: Some(value),
            unit,
            note: note.into(),
        });
    }

    pub(super) fn note(&mut self, model: &str, section: &'static str, metric: &str, note: String) {
        self.rows.push(Row {
            model: model.to_string(),
            section,
            metric: metric.to_string(),
            threads: None,
            value: None,
            unit: "",
            note,
        });
    }

    pub(super) fn cells(&self) -> Vec<[String; 7]> {
        self.rows
            .iter()
            .map(|r| {
                [
                    r.model.clone(),
                    r.section.to_string(),
                    r.metric.clone(),
                    r.threads.map_or(String::new(), |t| t.to_string()),
                    r.value.map_or(String::new(), format_value),
                    r.unit.to_string(),
                    r.note.clone(),
                ]
            })
            .collect()
    }

    /// Aligned text, one row per line, headed by [`COLUMNS`].
    pub(super) fn text(&self) -> String {
        let cells = self.cells();
        let mut width = COLUMNS.map(|c| c.chars().count());
        for row in &cells {
            for (w, c) in width.iter_mut().zip(row) {
                *w = (*w).max(c.chars().count());
            }
        }
        let line = |row: &[String]| {
            let mut s = String::new();
            for (i, (c, w)) in row.iter().zip(width).enumerate() {
                // Numbers right-aligned, the last column unpadded.
                if i == 4 {
                    let _ = write!(s, "{c:>w$}  ");
                } else if i + 1 == row.len() {
                    s.push_str(c);
                } else {
                    let _ = write!(s, "{c:<w$}  ");
                }
            }
            s.trim_end().to_string() + "\n"
        };
        let mut out = line(&COLUMNS.map(String::from));
        for row in &cells {
            out.push_str(&line(row));
        }
        out
    }

    pub(super) fn csv(&self) -> String {
        let field = |c: &str| {
            if c.contains([',', '"', '\n']) {
                format!("\"{}\"", c.replace('"', "\"\""))
            } else {
                c.to_string()
            }
        };
        let mut out = COLUMNS.join(",") + "\n";
        for row in self.cells() {
            out.push_str(&row.iter().map(|c| field(c)).collect::<Vec<_>>().join(","));
            out.push('\n');
        }
        out
    }
}

/// Four significant digits, no exponent for the usual magnitudes.
pub(super) fn format_value(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (3 - v.abs().log10().floor() as i32).clamp(0, 6) as usize;
    format!("{v:.digits$}")
}

/// "hit 59.0%, 1.234 M/CPU-s, 12% waiting"-style note of a raw measurement.
pub(super) fn cost_note(rays: usize, cost: &Cost) -> String {
    let mut note = String::new();
    if let Some(cpu) = cost.cpu.filter(|&c| c > 0.0) {
        let _ = write!(note, "{:.3} M per CPU-s", rays as f64 / cpu / 1e6);
    }
    if let Some(w) = cost.waiting() {
        let _ = write!(note, ", {:.0}% waiting for a core", 100.0 * w);
    }
    note
}

/// The note of a row carrying a target of the performance issue.
pub(super) fn target(what: &str, met: bool) -> String {
    format!("target {what}: {}", if met { "met" } else { "MISSED" })
}
