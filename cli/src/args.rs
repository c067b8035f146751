//! Command-line argument parsers shared by the commands.

/// [`tress_scene::check_threads`] as a command-line value parser.
pub fn parse_threads(s: &str) -> Result<usize, String> {
    tress_scene::check_threads(s.parse().map_err(|e| format!("{e}"))?)
}
