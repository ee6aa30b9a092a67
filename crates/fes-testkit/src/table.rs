//! The CSV files the tools write (figures' data, recordings) as a header and rows of
//! fields: they hold numbers and plain names, no quoting, so a split on commas reads them.

use std::path::Path;

/// The header's names and every row's fields of the CSV file at `path`; panics naming the
/// file when it cannot be read or has no header.
pub fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap_or_else(|| panic!("{}: no header", path.display()))
        .split(',')
        .map(String::from)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (header, rows)
}
