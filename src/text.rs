//! Text helpers for one-line error messages (the base layer: no imports from the crate).

/// Longest value (characters) quoted in an error message; longer ones are cut and end in "…".
pub const MAX_QUOTED_CHARS: usize = 80;

/// `s` cut to `max` characters, with "…" where it was cut.
pub fn clip(s: &str, max: usize) -> String {
    if s.chars().count() > max { format!("{}…", s.chars().take(max).collect::<String>()) } else { s.to_string() }
}

/// A value for an error message: at most [`MAX_QUOTED_CHARS`] characters.
pub fn quote_short(value: &str) -> String {
    clip(value, MAX_QUOTED_CHARS)
}

/// Cuts every quoted value of a message ('…', "…", `…` or […], opening at the start of a word) to
/// [`MAX_QUOTED_CHARS`] characters, so that a 5,000-character name or vector prints as 80 (serde's
/// and urdf-rs's messages quote the offending value and list the allowed ones: the list stays).
pub fn clip_quoted(msg: &str) -> String {
    let chars: Vec<char> = msg.chars().collect();
    let mut out = String::with_capacity(msg.len());
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let close = match c {
            '\'' | '"' | '`' => Some(c),
            '[' => Some(']'),
            _ => None,
        };
        let word_start = i == 0 || !chars[i - 1].is_alphanumeric();
        if let (Some(close), true) = (close, word_start)
            && let Some(len) = chars[i + 1..].iter().position(|&d| d == close)
            && len > MAX_QUOTED_CHARS
        {
            out.push(c);
            out.extend(&chars[i + 1..i + 1 + MAX_QUOTED_CHARS]);
            out.push('…');
            out.push(close);
            i += len + 2;
            continue;
        }
        out.push(c);
        i += 1;
    }
    out
}

/// Collapses a multi-line message to one line.
pub fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}
