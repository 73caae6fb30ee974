//! The shipped part of a Rust source file for the text guards (issue 39 item 4): every item under
//! `#[cfg(test)]` blanked, wherever it sits, and everything else kept. The guards used to cut the
//! file at its first `#[cfg(test)]`, which let a `#[cfg(test)] mod tests;` near the top hide the
//! rest of the file (most of `companion-link/src/vehicle/mod.rs`).
//!
//! A small lexer, not a parser: it knows comments (nested block comments too), strings (escapes,
//! raw strings), char literals against lifetimes, and bracket depth, which is what finding the end
//! of an item needs. Removed text becomes spaces, newlines stay: line numbers are kept.

use std::path::{Path, PathBuf};

const CFG_TEST: &str = "#[cfg(test)]";

/// Every `.rs` file below `dir`, into `out`.
pub(crate) fn rs_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rs_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `text` with every `#[cfg(test)]` item blanked (spaces; newlines kept).
pub(crate) fn shipped(text: &str) -> String {
    let b = text.as_bytes();
    let mut out: Vec<u8> = b.to_vec();
    let mut i = 0;
    while i < b.len() {
        if let Some(next) = skip_non_code(b, i) {
            i = next;
            continue;
        }
        if b[i..].starts_with(CFG_TEST.as_bytes()) {
            let end = item_end(b, i + CFG_TEST.len());
            for c in &mut out[i..end] {
                if *c != b'\n' {
                    *c = b' ';
                }
            }
            i = end;
            continue;
        }
        i += 1;
    }
    // Only ASCII bytes were replaced by ASCII spaces, and whole characters at that (a removed
    // range starts and ends on ASCII bytes): still UTF-8.
    String::from_utf8(out).unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned())
}

/// When a comment, string or char literal starts at `i`: the index just after it.
fn skip_non_code(b: &[u8], i: usize) -> Option<usize> {
    let at = |k: usize| b.get(k).copied();
    match b[i] {
        b'/' if at(i + 1) == Some(b'/') => Some(
            b[i..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |p| i + p),
        ),
        b'/' if at(i + 1) == Some(b'*') => {
            let mut depth = 0usize;
            let mut k = i;
            while k < b.len() {
                if b[k..].starts_with(b"/*") {
                    depth += 1;
                    k += 2;
                } else if b[k..].starts_with(b"*/") {
                    depth -= 1;
                    k += 2;
                    if depth == 0 {
                        return Some(k);
                    }
                } else {
                    k += 1;
                }
            }
            Some(b.len())
        }
        b'"' => Some(string_end(b, i + 1)),
        b'b' | b'c' if at(i + 1) == Some(b'"') && !is_ident_byte(before(b, i)) => {
            Some(string_end(b, i + 2))
        }
        b'r' | b'b' | b'c' if !is_ident_byte(before(b, i)) => raw_string_end(b, i),
        b'\'' => char_end(b, i),
        _ => None,
    }
}

fn before(b: &[u8], i: usize) -> Option<u8> {
    i.checked_sub(1).map(|p| b[p])
}

fn is_ident_byte(c: Option<u8>) -> bool {
    c.is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_')
}

/// After the opening quote of a plain string: the index after its closing quote.
fn string_end(b: &[u8], mut k: usize) -> usize {
    while k < b.len() {
        match b[k] {
            b'\\' => k += 2,
            b'"' => return k + 1,
            _ => k += 1,
        }
    }
    b.len()
}

/// `r"..."`, `r#"..."#`, `br##"..."##`, `cr"..."` starting at `i`: the index after it.
fn raw_string_end(b: &[u8], i: usize) -> Option<usize> {
    let mut k = i;
    if b[k] == b'b' || b[k] == b'c' {
        k += 1;
    }
    if b.get(k) != Some(&b'r') {
        return None;
    }
    k += 1;
    let hashes = b[k..].iter().take_while(|&&c| c == b'#').count();
    k += hashes;
    if b.get(k) != Some(&b'"') {
        return None;
    }
    k += 1;
    let mut close = vec![b'"'];
    close.extend(std::iter::repeat_n(b'#', hashes));
    Some(
        b[k..]
            .windows(close.len())
            .position(|w| w == close.as_slice())
            .map_or(b.len(), |p| k + p + close.len()),
    )
}

/// A char literal at `i` (`'a'`, `'\n'`, `'\u{7f}'`, `'{'`): the index after it; a lifetime or
/// label (`'a`, `'static`): None.
fn char_end(b: &[u8], i: usize) -> Option<usize> {
    match b.get(i + 1)? {
        b'\\' => {
            // The escaped character first: `'\''` and `'\\'` end at the quote after it.
            let close = b.get(i + 3..)?.iter().position(|&c| c == b'\'')?;
            Some(i + 3 + close + 1)
        }
        _ => {
            // One character (possibly multi-byte) then a quote.
            let ch_len = std::str::from_utf8(&b[i + 1..(i + 5).min(b.len())])
                .map_or_else(|e| e.valid_up_to(), |s| s.len())
                .min(4);
            let first = std::str::from_utf8(&b[i + 1..i + 1 + ch_len.max(1)])
                .ok()
                .and_then(|s| s.chars().next())?;
            let after = i + 1 + first.len_utf8();
            (b.get(after) == Some(&b'\'')).then_some(after + 1)
        }
    }
}

/// From just after `#[cfg(test)]`: the end of the item it gates (after its `;` at depth 0, or
/// after the `}` that closes its first `{` at depth 0).
fn item_end(b: &[u8], start: usize) -> usize {
    let mut depth = 0i32;
    let mut k = start;
    while k < b.len() {
        if let Some(next) = skip_non_code(b, k) {
            k = next;
            continue;
        }
        match b[k] {
            b'(' | b'[' | b'{' => depth += 1,
            b')' | b']' => depth -= 1,
            b'}' => {
                depth -= 1;
                if depth == 0 {
                    return k + 1;
                }
            }
            b';' if depth == 0 => return k + 1,
            _ => {}
        }
        k += 1;
        // An attribute before the item (`#[cfg(test)] #[allow(x)] mod t {}`) opens and closes
        // a `[` at depth 0: that is no end, the scan goes on to the item.
    }
    b.len()
}

/// The shipped code of `text` ([`shipped`]) with comments and the contents of string and char
/// literals blanked too (line numbers kept): what a guard over identifiers and types reads.
#[allow(dead_code)]
pub(crate) fn code_only(text: &str) -> String {
    let kept = shipped(text);
    let b = kept.as_bytes();
    let mut out = b.to_vec();
    let mut i = 0;
    while i < b.len() {
        if let Some(next) = skip_non_code(b, i) {
            let literal = matches!(b[i], b'"' | b'\'' | b'b' | b'c' | b'r');
            // A literal keeps its quotes (so `""` is still an expression); its inside goes.
            let (from, to) = if literal {
                (i + 1, next.saturating_sub(1).max(i + 1))
            } else {
                (i, next)
            };
            for c in &mut out[from..to] {
                if c.is_ascii() && *c != b'\n' {
                    *c = b' ';
                } else if !c.is_ascii() {
                    *c = b' ';
                }
            }
            i = next;
            continue;
        }
        i += 1;
    }
    String::from_utf8(out).unwrap_or_default()
}
