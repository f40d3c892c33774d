//! The layer rule of `docs/architecture.md` ("Layers"), checked on the sources: every
//! `crate::` path outside comments, in every file of this crate, names a module of a lower
//! layer than the file's own module (or its own). The table in the document is the one
//! source of the rule.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The layer of each module, read from the table under "## Layers" of
/// `docs/architecture.md`: rows `| n | `module` | ... |`.
fn layer_table(doc: &str) -> HashMap<String, usize> {
    let section = doc
        .split("\n## Layers\n")
        .nth(1)
        .expect("docs/architecture.md has a section '## Layers'");
    let section = section.split("\n## ").next().unwrap_or(section);
    let mut table = HashMap::new();
    for line in section.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() < 4 {
            continue;
        }
        let (Ok(layer), Some(module)) = (
            cells[1].parse::<usize>(),
            cells[2].strip_prefix('`').and_then(|c| c.strip_suffix('`')),
        ) else {
            continue;
        };
        assert!(
            table.insert(module.to_string(), layer).is_none(),
            "module '{module}' twice in the layer table"
        );
    }
    assert!(!table.is_empty(), "the layer table has no rows");
    table
}

/// The source without comments (line comments, doc comments and block comments) and string
/// literals' contents, so that only code is read.
fn code_of(source: &str) -> String {
    let mut out = String::with_capacity(source.len());
    let b = source.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            let mut depth = 0;
            while i < b.len() {
                if b[i..].starts_with(b"/*") {
                    depth += 1;
                    i += 2;
                } else if b[i..].starts_with(b"*/") {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if b[i] == b'\'' {
            // a char literal (`'"'`, `'\''`) is skipped whole; a lifetime (`'a`) is code
            let close = if b.get(i + 1) == Some(&b'\\') {
                i + 3
            } else {
                i + 2
            };
            if b.get(close) == Some(&b'\'') {
                i = close + 1;
                out.push_str("' '");
            } else {
                out.push('\'');
                i += 1;
            }
        } else if b[i] == b'r'
            && matches!(b.get(i + 1), Some(b'"' | b'#'))
            && !b[..i]
                .last()
                .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
        {
            // a raw string `r"..."`, `r#"..."#`: to its closing quote and as many `#`
            let hashes = b[i + 1..].iter().take_while(|&&c| c == b'#').count();
            let close: Vec<u8> = std::iter::once(b'"')
                .chain(std::iter::repeat_n(b'#', hashes))
                .collect();
            let body = i + 2 + hashes;
            i = b[body..]
                .windows(close.len())
                .position(|w| w == close.as_slice())
                .map_or(b.len(), |k| body + k + close.len());
            out.push_str("\"\"");
        } else if b[i] == b'"' {
            // a plain string literal (raw strings in this crate hold no `crate::`)
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("\"\"");
        } else {
            out.push(b[i] as char);
            i += 1;
        }
    }
    out
}

/// The first segments of the `crate::` paths in `code`, with those of grouped imports
/// (`crate::{a, b::c}`).
fn imported_modules(code: &str) -> Vec<String> {
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        let before = code[..at].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || matches!(c, '_' | '$' | ':')) {
            continue; // `$crate::` in macros, a longer name, or a path's inner segment
        }
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let end = group.find('}').unwrap_or(group.len());
            for item in group[..end].split(',') {
                let name = ident(item.trim());
                if !name.is_empty() {
                    out.push(name);
                }
            }
        } else {
            out.push(ident(rest));
        }
    }
    out
}

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("the source folder is readable") {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn imports_follow_the_layer_table() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = std::fs::read_to_string(root.join("../../docs/architecture.md"))
        .expect("docs/architecture.md is readable");
    let table = layer_table(&doc);
    let src = root.join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    files.sort();
    let mut against = Vec::new();
    for file in &files {
        let relative = file.strip_prefix(&src).expect("a file under src");
        let module = relative
            .components()
            .next()
            .and_then(|c| c.as_os_str().to_str())
            .map(|c| c.trim_end_matches(".rs").to_string())
            .expect("a path");
        if module == "lib" || module == "layers" {
            continue; // the crate root re-exports from any layer; this file is the test
        }
        let Some(&own) = table.get(&module) else {
            against.push(format!(
                "{}: module '{module}' has no row in the layer table",
                relative.display()
            ));
            continue;
        };
        let code = code_of(&std::fs::read_to_string(file).expect("a readable source file"));
        let mut seen = Vec::new();
        for target in imported_modules(&code) {
            if target == module || seen.contains(&target) {
                continue;
            }
            seen.push(target.clone());
            match table.get(&target) {
                Some(&layer) if layer < own => {}
                Some(&layer) => against.push(format!(
                    "{}: '{module}' (layer {own}) imports '{target}' (layer {layer})",
                    relative.display()
                )),
                None => against.push(format!(
                    "{}: '{module}' (layer {own}) imports 'crate::{target}', which is the crate root or not in the layer table",
                    relative.display()
                )),
            }
        }
    }
    assert!(
        against.is_empty(),
        "{} imports against the layer table of docs/architecture.md:\n{}",
        against.len(),
        against.join("\n")
    );
}

#[test]
fn the_reader_sees_grouped_imports_and_skips_comments_and_strings() {
    let code = code_of(
        "use crate::{a, b::c};\n// crate::d\n/// crate::e\nlet s = \"crate::f\";\n/* crate::g */ $crate::h; x::crate::i; crate::j::k",
    );
    assert_eq!(imported_modules(&code), ["a", "b", "j"]);
    // char literals holding a quote, raw strings and lifetimes do not hide what follows
    let code = code_of(
        "let q = '\"'; let e = '\\''; let r = r#\"crate::x \" y\"#; fn f<'a>(s: &'a str) { crate::m::n }",
    );
    assert_eq!(imported_modules(&code), ["m"]);
    let doc = "x\n## Layers\n| layer | module | what |\n|---|---|---|\n| 1 | `m` | w |\n| 2 | `n` | w |\n## Next\n| 3 | `o` | w |\n";
    let table = layer_table(doc);
    assert_eq!(table.len(), 2);
    assert_eq!((table["m"], table["n"]), (1, 2));
}
