//! WITSML time logs, as servers write them: WITSML 1.4.1 (`<logs><log>`, its rows in
//! `<logData>` under a `<mnemonicList>` and a `<unitList>`) and WITSML 2.0 (`<Log>` or a bare
//! `<ChannelSet>`, its channels' `<Mnemonic>` and `<Uom>`, its rows in `<Data><Data>` as
//! JSON arrays `[[index], [values]]`). Each channel becomes a column named `MNEMONIC [unit]`,
//! so that its role and unit are read by the rules of a CSV header (rig mnemonics, bracketed
//! units), and each row a record of text cells read by the CSV's rules, its line the XML's.
//! Null values (empty, the log's or the curve's `nullValue`, `null`, `NaN`) leave their row
//! out where they fall in a column the record reads, and the rows left out are said.

use crate::error::{Error, Result};
use std::path::Path;

/// A log read from XML: its channels' names (`MNEMONIC [unit]`), the index channel's, and its
/// rows of text cells with the XML line each is on.
pub struct Log {
    pub headers: csv::StringRecord,
    /// The index channel's column (the log's `indexCurve` / `Index`), where it is a time.
    pub time_index: Option<usize>,
    pub rows: Vec<(csv::StringRecord, u64)>,
    /// Per channel, the texts that mean "no value" besides empty and `NaN`.
    pub nulls: Vec<Vec<String>>,
}

/// Whether a record's text is XML (its first non-blank character, after a byte-order mark,
/// is `<`): a WITSML log, not a CSV.
pub fn is_xml(text: &[u8]) -> bool {
    let text = text.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(text);
    text.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'<')
}

/// Whether a cell holds no value: empty, `NaN`, `null` (2.0) or one of the log's null texts.
pub fn is_null(cell: &str, nulls: &[String]) -> bool {
    let cell = cell.trim();
    cell.is_empty()
        || cell.eq_ignore_ascii_case("nan")
        || cell.eq_ignore_ascii_case("null")
        || nulls.iter().any(|n| {
            n == cell
                || n.parse::<f64>()
                    .ok()
                    .zip(cell.parse::<f64>().ok())
                    .is_some_and(|(a, b): (f64, f64)| a.to_bits() == b.to_bits())
        })
}

/// Reads the WITSML log in `text` (named `path` in messages).
pub fn read(text: &str, path: &Path) -> Result<Log> {
    let refuse = |line: Option<u64>, message: String| Error::Format {
        path: path.to_path_buf(),
        line,
        message,
    };
    let doc = roxmltree::Document::parse(text).map_err(|e| {
        let at = e.pos();
        let said = e.to_string();
        let said = said
            .strip_suffix(&format!(" at {}:{}", at.row, at.col))
            .unwrap_or(&said);
        refuse(
            Some(u64::from(at.row)),
            format!("column {}: the XML does not parse: {said}", at.col),
        )
    })?;
    let root = doc.root_element();
    match root.tag_name().name() {
        "logs" => read_141(only_child(&doc, root, "log", path)?, &doc, path),
        "log" => read_141(root, &doc, path),
        "Log" => read_20(only_child(&doc, root, "ChannelSet", path)?, &doc, path),
        "ChannelSet" => read_20(root, &doc, path),
        other => Err(refuse(
            Some(line_of(&doc, root)),
            format!("an XML file whose root is <{other}>, not a WITSML log (<logs>, <log>, <Log> or <ChannelSet>)"),
        )),
    }
}

/// The line `node` starts on.
fn line_of(doc: &roxmltree::Document, node: roxmltree::Node) -> u64 {
    u64::from(doc.text_pos_at(node.range().start).row)
}

/// The one child of `parent` named `name`: a file holds one record, so none or several are
/// refused (several at the second's line).
fn only_child<'a, 'i>(
    doc: &roxmltree::Document,
    parent: roxmltree::Node<'a, 'i>,
    name: &'static str,
    path: &Path,
) -> Result<roxmltree::Node<'a, 'i>> {
    let parent_name = parent.tag_name().name();
    let found: Vec<_> = children(parent, name).collect();
    match found.as_slice() {
        [one] => Ok(*one),
        [] => Err(Error::Format {
            path: path.to_path_buf(),
            line: None,
            message: format!("the WITSML <{parent_name}> holds no <{name}>"),
        }),
        many => Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(line_of(doc, many[1])),
            message: format!(
                "the WITSML <{parent_name}> holds {} <{name}> elements; bitrock reads one record at a time: keep one <{name}> per file",
                many.len()
            ),
        }),
    }
}

/// The element children of `node` named `name` (any namespace).
fn children<'a, 'i>(
    node: roxmltree::Node<'a, 'i>,
    name: &'static str,
) -> impl Iterator<Item = roxmltree::Node<'a, 'i>> {
    node.children()
        .filter(move |c| c.is_element() && c.tag_name().name() == name)
}

/// The trimmed text of `node`'s first child element named `name`.
fn child_text<'a>(node: roxmltree::Node<'a, '_>, name: &'static str) -> Option<&'a str> {
    children(node, name).next().and_then(|c| c.text()).map(str::trim)
}

/// A channel's column name: its mnemonic, and its unit in brackets where it has one.
fn column_name(mnemonic: &str, unit: Option<&str>) -> String {
    match unit
        .map(str::trim)
        .filter(|u| !u.is_empty() && !u.eq_ignore_ascii_case("unitless"))
    {
        Some(unit) => format!("{mnemonic} [{unit}]"),
        None => mnemonic.to_string(),
    }
}

/// Whether a log's index type is a time (`date time`, `elapsed time`), not a depth.
fn is_time_index(index_type: Option<&str>) -> bool {
    index_type.is_none_or(|t| t.to_ascii_lowercase().contains("time"))
}

/// A WITSML 1.4.1 `<log>`.
fn read_141(log: roxmltree::Node, doc: &roxmltree::Document, path: &Path) -> Result<Log> {
    let refuse = |node: roxmltree::Node, message: String| Error::Format {
        path: path.to_path_buf(),
        line: Some(line_of(doc, node)),
        message,
    };
    let curves: Vec<_> = children(log, "logCurveInfo").collect();
    let blocks: Vec<_> = children(log, "logData").collect();
    let Some(first) = blocks.first() else {
        return Err(refuse(log, "the WITSML log holds no <logData>: no rows to read".into()));
    };
    let delimiter = child_text(log, "dataDelimiter")
        .filter(|d| !d.is_empty())
        .unwrap_or(",")
        .to_string();
    let split = |text: &str| -> Vec<String> { text.split(delimiter.as_str()).map(|c| c.trim().to_string()).collect() };
    let mnemonics = match child_text(*first, "mnemonicList") {
        Some(list) => split(list),
        None => curves
            .iter()
            .filter_map(|c| child_text(*c, "mnemonic"))
            .map(str::to_string)
            .collect(),
    };
    let curve = |mnemonic: &str| {
        curves
            .iter()
            .find(|c| child_text(**c, "mnemonic").is_some_and(|m| m.eq_ignore_ascii_case(mnemonic)))
    };
    let units: Vec<Option<String>> = match child_text(*first, "unitList") {
        Some(list) => split(list).into_iter().map(Some).collect(),
        None => mnemonics
            .iter()
            .map(|m| curve(m).and_then(|c| child_text(*c, "unit")).map(str::to_string))
            .collect(),
    };
    if units.len() != mnemonics.len() {
        return Err(refuse(
            *first,
            format!(
                "the <unitList> names {} units for {} mnemonics",
                units.len(),
                mnemonics.len()
            ),
        ));
    }
    let log_null = child_text(log, "nullValue").map(str::to_string);
    let nulls = mnemonics
        .iter()
        .map(|m| {
            let own = curve(m).and_then(|c| child_text(*c, "nullValue")).map(str::to_string);
            own.into_iter().chain(log_null.clone()).collect()
        })
        .collect();
    let headers: csv::StringRecord = mnemonics
        .iter()
        .zip(&units)
        .map(|(m, u)| column_name(m, u.as_deref()))
        .collect();
    let index = child_text(log, "indexCurve")
        .and_then(|name| mnemonics.iter().position(|m| m.eq_ignore_ascii_case(name)))
        .filter(|_| is_time_index(child_text(log, "indexType")));
    let mut rows = Vec::new();
    for block in &blocks {
        if let Some(list) = child_text(*block, "mnemonicList")
            && split(list) != mnemonics
        {
            return Err(refuse(
                *block,
                "this <logData> lists other mnemonics than the first: one record has one set of columns".into(),
            ));
        }
        for data in children(*block, "data") {
            let text = data.text().unwrap_or("").trim();
            if text.is_empty() {
                continue;
            }
            let cells = split(text);
            if cells.len() != mnemonics.len() {
                return Err(refuse(
                    data,
                    format!("a row of {} values for {} mnemonics", cells.len(), mnemonics.len()),
                ));
            }
            rows.push((csv::StringRecord::from(cells), line_of(doc, data)));
        }
    }
    Ok(Log {
        headers,
        time_index: index,
        rows,
        nulls,
    })
}

/// A WITSML 2.0 `<ChannelSet>`.
fn read_20(set: roxmltree::Node, doc: &roxmltree::Document, path: &Path) -> Result<Log> {
    let refuse = |line: u64, message: String| Error::Format {
        path: path.to_path_buf(),
        line: Some(line),
        message,
    };
    let index = children(set, "Index").next();
    let index_name = index.and_then(|i| child_text(i, "Mnemonic")).unwrap_or("index");
    let index_unit = index.and_then(|i| child_text(i, "Uom"));
    let time_index = is_time_index(index.and_then(|i| child_text(i, "IndexType")));
    let channels: Vec<_> = children(set, "Channel").collect();
    let mut headers = vec![column_name(index_name, index_unit)];
    headers.extend(
        channels
            .iter()
            .map(|c| column_name(child_text(*c, "Mnemonic").unwrap_or("?"), child_text(*c, "Uom"))),
    );
    let Some(data) = children(set, "Data").next().and_then(|d| children(d, "Data").next()) else {
        return Err(refuse(
            line_of(doc, set),
            "the WITSML channel set holds no <Data><Data>: no rows to read".into(),
        ));
    };
    let body = data.text().unwrap_or("");
    // The body's line in the file, so that a row's line is the file's.
    let body_start = data.first_child().map_or(data.range().start, |t| t.range().start);
    let first_line = u64::from(doc.text_pos_at(body_start).row);
    let mut rows = Vec::new();
    for (row, offset_lines) in json_rows(body).map_err(|(lines, message)| refuse(first_line + lines, message))? {
        let line = first_line + offset_lines;
        let value: serde_json::Value = serde_json::from_str(&row).map_err(|e| {
            refuse(
                line,
                format!("a data row that is not a JSON array ([[index], [values]]): {e}"),
            )
        })?;
        let parts = value.as_array().filter(|p| p.len() == 2);
        let (Some(index), Some(values)) = (
            parts.and_then(|p| p[0].as_array()).and_then(|i| i.first()),
            parts.and_then(|p| p[1].as_array()),
        ) else {
            return Err(refuse(line, "a data row that is not [[index], [values]]".into()));
        };
        if values.len() > channels.len() {
            return Err(refuse(
                line,
                format!("a row of {} values for {} channels", values.len(), channels.len()),
            ));
        }
        let mut cells = vec![cell(index)];
        cells.extend(values.iter().map(cell));
        // A short row's missing tail is null.
        cells.resize(channels.len() + 1, String::new());
        rows.push((csv::StringRecord::from(cells), line));
    }
    Ok(Log {
        nulls: vec![Vec::new(); headers.len()],
        headers: csv::StringRecord::from(headers),
        time_index: time_index.then_some(0),
        rows,
    })
}

/// A JSON value as a cell's text: a string's contents, a number as written, `null` empty, a
/// value with its point metadata (`[value, flag]`) as its value.
fn cell(value: &serde_json::Value) -> String {
    match value {
        serde_json::Value::Null => String::new(),
        serde_json::Value::String(s) => s.clone(),
        serde_json::Value::Array(a) => a.first().map_or_else(String::new, cell),
        other => other.to_string(),
    }
}

/// The rows of a WITSML 2.0 data body (`[ row, row, … ]`, each row a JSON array), with the
/// line each starts on counted from the body's first line; a trailing comma before a closing
/// bracket (which some servers write) is dropped. `Err` gives the line and what is wrong.
fn json_rows(body: &str) -> std::result::Result<Vec<(String, u64)>, (u64, String)> {
    let mut rows = Vec::new();
    let mut depth = 0usize;
    let mut line = 0u64;
    let mut in_string = false;
    let mut escaped = false;
    let mut row = String::new();
    let mut row_line = 0;
    let mut seen_outer = false;
    for c in body.chars() {
        if c == '\n' {
            line += 1;
        }
        if in_string {
            row.push(c);
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_string = false,
                _ => {}
            }
            continue;
        }
        match c {
            '[' => {
                depth += 1;
                if depth == 1 {
                    seen_outer = true;
                    continue;
                }
                if depth == 2 {
                    row.clear();
                    row_line = line;
                }
                row.push(c);
            }
            ']' => {
                if depth == 0 {
                    return Err((line, "a ']' closes no '['".into()));
                }
                depth -= 1;
                if depth >= 1 {
                    // A trailing comma before this bracket.
                    let trimmed = row.trim_end().len();
                    if row[..trimmed].ends_with(',') {
                        row.truncate(trimmed - 1);
                    }
                    row.push(c);
                    if depth == 1 {
                        rows.push((std::mem::take(&mut row), row_line));
                    }
                }
            }
            '"' if depth >= 2 => {
                in_string = true;
                row.push(c);
            }
            _ if depth >= 2 => row.push(c),
            ',' | ' ' | '\t' | '\r' | '\n' => {}
            other => return Err((line, format!("'{other}' outside a row of the data"))),
        }
    }
    if depth != 0 || !seen_outer {
        return Err((
            line,
            "the data is not one JSON array of rows (a bracket is not closed)".into(),
        ));
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_rows_keep_their_lines_and_forgive_a_trailing_comma() {
        let body =
            "\n  [\n   [[\"2026-11-29T14:30:00Z\"], [1.5, null, \"a,]b\"]],\n   [[\"t\"], [[2.5, true], 3,]],\n  ]\n";
        let rows = json_rows(body).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(
            rows[0],
            ("[[\"2026-11-29T14:30:00Z\"], [1.5, null, \"a,]b\"]]".to_string(), 2)
        );
        assert_eq!(rows[1].1, 3);
        let v: serde_json::Value = serde_json::from_str(&rows[1].0).unwrap();
        assert_eq!(cell(&v[1][0]), "2.5");
        assert_eq!(cell(&v[1][1]), "3");
        assert!(json_rows("[[1], [2]").is_err());
    }

    #[test]
    fn nulls_are_empty_nan_null_or_the_logs_own() {
        let nulls = vec!["-999.25".to_string()];
        for text in ["", " ", "NaN", "null", "-999.25", "-999.2500"] {
            assert!(is_null(text, &nulls), "{text:?}");
        }
        assert!(!is_null("0", &nulls));
        assert!(is_xml(b"\xEF\xBB\xBF  \n<?xml version=\"1.0\"?>"));
        assert!(!is_xml(b"time_s,speed_rpm"));
    }
}
