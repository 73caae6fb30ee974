//! Test support: the STATUSTEXTs in a batch of messages as a ground station shows them, the
//! MAVLink 2 chunks of one text (one non-zero `id`, `chunk_seq` 0, 1, ...) joined.

use companion_link::Msg;

/// Each text once, chunks joined, in the order sent.
pub(crate) fn statustexts(out: &[Msg]) -> Vec<String> {
    let mut texts: Vec<String> = Vec::new();
    let mut open: Option<u16> = None;
    for m in out {
        let Msg::STATUSTEXT(st) = m else { continue };
        let part = st.text.to_str().unwrap_or_default();
        match (open, texts.last_mut()) {
            (Some(id), Some(last)) if st.id == id && st.chunk_seq > 0 => last.push_str(part),
            _ => texts.push(part.to_string()),
        }
        open = (st.id != 0).then_some(st.id);
    }
    texts
}
