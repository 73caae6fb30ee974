//! Building the overlay's TOML: nested tables by path, numbers rounded to what a fit supports.

use toml::{Table, Value};

/// Four significant decimals are more than any fit here supports.
pub(super) fn round4(x: f64) -> Value {
    Value::Float((x * 1e4).round() / 1e4)
}

/// Six decimals: the polynomial's small higher coefficients.
pub(super) fn round6(x: f64) -> Value {
    Value::Float((x * 1e6).round() / 1e6)
}

/// The table at `path` below `t`, made where missing.
pub(super) fn table_at<'a>(t: &'a mut Table, path: &[&str]) -> &'a mut Table {
    let mut cur = t;
    for k in path {
        cur = cur
            .entry(k.to_string())
            .or_insert_with(|| Value::Table(Table::new()))
            .as_table_mut()
            .expect("built as tables");
    }
    cur
}
