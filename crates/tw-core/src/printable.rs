//! Making text that came from a file safe to print in a message.
//!
//! Why: error messages quote file content (a keyword, a name, a URI). Raw control characters in
//! that content, written to a terminal, are commands to it: ESC starts escape sequences that can
//! recolour, move the cursor, rewrite the title or the visible history, BEL rings, and the C1
//! control CSI (U+009B) is ESC [ on terminals that honour C1. [`escape_controls`] replaces every
//! such character by a visible escape (`\x1b`, `\x07`, `\u{9b}`), keeping tab and newline, so a
//! message shows exactly what is in the file and nothing acts on the terminal.

use std::borrow::Cow;
use std::fmt::Write;

/// Whether `c` is escaped by [`escape_controls`]: C0 controls except tab and newline, DEL, and
/// the C1 controls U+0080..=U+009F.
pub fn is_unsafe_control(c: char) -> bool {
    (c.is_control() && c != '\t' && c != '\n') || ('\u{80}'..='\u{9f}').contains(&c)
}

/// `s` with every control character that could act on a terminal written as an escape: `\x1b`
/// for C0 controls and DEL, `\u{9b}` for C1 controls. Borrows when there is nothing to escape.
pub fn escape_controls(s: &str) -> Cow<'_, str> {
    if !s.chars().any(is_unsafe_control) {
        return Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        if !is_unsafe_control(c) {
            out.push(c);
        } else if (c as u32) < 0x80 {
            let _ = write!(out, "\\x{:02x}", c as u32);
        } else {
            let _ = write!(out, "\\u{{{:x}}}", c as u32);
        }
    }
    Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn controls_are_escaped_and_text_kept() {
        assert!(matches!(escape_controls("plain text, ünïcode\tand\nlines"), Cow::Borrowed(_)));
        assert_eq!(escape_controls("a\x1b[2Jb\x07c\x7f\rd\0"), "a\\x1b[2Jb\\x07c\\x7f\\x0dd\\x00");
        assert_eq!(escape_controls("x\u{9b}31m"), "x\\u{9b}31m");
        assert_eq!(escape_controls("tab\tnewline\n"), "tab\tnewline\n");
    }
}
