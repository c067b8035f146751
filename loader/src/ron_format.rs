//! RON as tress reads and writes it.

/// RON options for everything tress parses: newtype variants may omit their inner parentheses,
/// so `Chiang(beta_m: 0.3)` and `Path(max_depth: 8)` read naturally.
pub fn options() -> ron::Options {
    ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES)
}

/// Where a RON text fails to parse, and why: printed `line:column: what`, followed by the
/// offending line with a caret under the column.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{line}:{column}: {code}{excerpt}")]
pub struct SyntaxError {
    /// 1-based line.
    pub line: usize,
    /// 1-based column, in characters.
    pub column: usize,
    /// What RON found wrong.
    pub code: ron::error::Error,
    /// The line, cut to at most [`EXCERPT_CHARS`] characters around the column, with the caret
    /// under it, on two indented lines of their own (empty when the line is not in the text).
    excerpt: String,
}

/// Longest excerpt of a line shown under a syntax error: a one-line file of 400 KB is not
/// printed whole.
const EXCERPT_CHARS: usize = 120;

impl SyntaxError {
    /// The error RON gave parsing `text`.
    pub fn new(text: &str, error: ron::error::SpannedError) -> Self {
        let p = error.span.start;
        let excerpt = match text.lines().nth(p.line.saturating_sub(1)) {
            Some(line) => {
                let (shown, caret) = excerpt(line, p.col.saturating_sub(1));
                format!("\n    {shown}\n    {}^", " ".repeat(caret))
            }
            None => String::new(),
        };
        SyntaxError {
            line: p.line,
            column: p.col,
            code: error.code,
            excerpt,
        }
    }
}

/// At most [`EXCERPT_CHARS`] characters of `line` around character `col`, with `…` where it
/// is cut, and the caret's column in that excerpt.
fn excerpt(line: &str, col: usize) -> (String, usize) {
    let chars: Vec<char> = line.chars().collect();
    if chars.len() <= EXCERPT_CHARS {
        return (line.to_owned(), col.min(chars.len()));
    }
    let col = col.min(chars.len());
    let start = col.saturating_sub(EXCERPT_CHARS / 2);
    let end = (start + EXCERPT_CHARS).min(chars.len());
    let start = end.saturating_sub(EXCERPT_CHARS);
    let mut shown: String = chars[start..end].iter().collect();
    let mut caret = col - start;
    if start > 0 {
        shown.insert(0, '…');
        caret += 1;
    }
    if end < chars.len() {
        shown.push('…');
    }
    (shown, caret)
}
