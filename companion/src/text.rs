//! The two ways text from a log leaves the process: into HTML (escaped, text and attributes
//! alike) and onto a terminal (control characters and escape sequences removed, so a crafted
//! STATUSTEXT cannot move the cursor, recolour or retitle the operator's terminal).

/// Escape for HTML text and for double- or single-quoted attribute values.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            _ => o.push(c),
        }
    }
    o
}

/// Unicode bidirectional overrides and isolates: they reorder what the terminal shows.
fn is_bidi_control(c: char) -> bool {
    matches!(c, '\u{200E}' | '\u{200F}' | '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}')
}

/// Text for the terminal: ANSI escape sequences (CSI `ESC [ ... final`, OSC `ESC ] ... BEL/ST`)
/// dropped whole, every other control character (C0, DEL, C1) and bidi override dropped; tabs
/// and newlines become spaces (one log value is one line).
pub fn clean(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    let mut it = s.chars().peekable();
    while let Some(c) = it.next() {
        match c {
            '\u{1b}' | '\u{9b}' => {
                let kind = if c == '\u{9b}' {
                    Some('[')
                } else {
                    it.peek().copied()
                };
                match kind {
                    Some('[') => {
                        if c == '\u{1b}' {
                            it.next();
                        }
                        // Parameters and intermediates, then one final byte in @..~.
                        for d in it.by_ref() {
                            if ('@'..='~').contains(&d) {
                                break;
                            }
                        }
                    }
                    Some(']') | Some('P') | Some('_') | Some('^') => {
                        it.next();
                        // String sequences end at BEL or ST (ESC \).
                        while let Some(d) = it.next() {
                            if d == '\u{7}' || d == '\u{9c}' {
                                break;
                            }
                            if d == '\u{1b}' {
                                if it.peek() == Some(&'\\') {
                                    it.next();
                                }
                                break;
                            }
                        }
                    }
                    Some(_) => {
                        it.next();
                    }
                    None => {}
                }
            }
            '\t' | '\n' | '\r' => o.push(' '),
            c if c.is_control() || is_bidi_control(c) => {}
            c => o.push(c),
        }
    }
    o
}

/// Text for the terminal with every control character (C0, DEL, C1, and `\n` unless
/// `keep_newlines`) and bidi override written as its Rust escape (`\u{1b}`, `\t`), the rest as
/// is: for paths and params strings, where the reader needs to see what is there (a folder named
/// with an escape sequence is shown, not obeyed).
pub fn escape_controls(s: &str, keep_newlines: bool) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        if c == '\n' && keep_newlines {
            o.push(c);
        } else if c.is_control() || is_bidi_control(c) {
            o.extend(c.escape_debug());
        } else {
            o.push(c);
        }
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn html_escape_covers_text_and_both_attribute_quotes() {
        assert_eq!(
            esc(r#"<script>"x"'y'&"#),
            "&lt;script&gt;&quot;x&quot;&#39;y&#39;&amp;"
        );
    }

    #[test]
    fn terminal_text_has_no_control_characters_or_escape_sequences() {
        let evil = "ok\x1b[2J\x1b[31mred\x1b]0;title\x07 \x07bell\x08\x00\u{9b}1mc1\u{202e}txt\ttab\nnl\x7f";
        let c = clean(evil);
        assert_eq!(c, "okred bellc1txt tab nl");
        assert!(!c.chars().any(|ch| ch.is_control()));
    }

    #[test]
    fn escaped_text_shows_control_characters_without_sending_them() {
        let evil = "run\x1b[2J\x1b]0;t\x07\u{9b}1m\u{202e}a\tb\r\nc";
        let e = escape_controls(evil, false);
        assert_eq!(
            e,
            "run\\u{1b}[2J\\u{1b}]0;t\\u{7}\\u{9b}1m\\u{202e}a\\tb\\r\\nc"
        );
        assert!(!e.chars().any(|ch| ch.is_control()));
        assert_eq!(escape_controls("a\nb\x1b", true), "a\nb\\u{1b}");
    }
}
