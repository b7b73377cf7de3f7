//! The library's layers, kept true: every module imports only from its own layer or the layers
//! below it (the layout table of docs/layout.md), and no two top-level modules import each other
//! through any path. Read from the source itself: `crate::` and `super::` paths outside
//! comments and test modules.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Each top-level module of the library and its layer, lowest first.
const LAYERS: [(&str, u8); 21] = [
    ("error", 0),
    ("units", 0),
    ("rng", 0),
    ("numerics", 0),
    ("limits", 0),
    ("memo", 0),
    ("data", 0),
    ("files", 0),
    ("laws", 1),
    ("fit", 1),
    ("prior", 1),
    ("stability", 1),
    ("simulate", 1),
    ("separation", 1),
    ("eval", 2),
    ("abc", 3),
    ("documents", 3),
    ("run", 4),
    ("report", 5),
    ("bench", 5),
    ("watch", 6),
];

/// The source of a file without comments and without its test module.
fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let text = text.split("#[cfg(test)]").next().unwrap();
    text.lines()
        .map(|l| l.split("//").next().unwrap())
        .collect::<Vec<_>>()
        .join("\n")
}

/// The library's source files (the binary's `main.rs` and `cli/` left out), each with its path
/// relative to `src/`.
fn library_files() -> Vec<(String, std::path::PathBuf)> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    let mut stack = vec![src.clone()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            let rel = path.strip_prefix(&src).unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                if rel != "cli" {
                    stack.push(path);
                }
            } else if rel != "main.rs" && rel.ends_with(".rs") {
                files.push((rel, path));
            }
        }
    }
    files
}

/// Top-level module → the top-level modules it refers to.
fn imports() -> BTreeMap<String, BTreeSet<String>> {
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (rel, path) in library_files() {
        if rel == "lib.rs" {
            continue;
        }
        let module = rel.split(['/', '.']).next().unwrap().to_string();
        let nested = rel.contains('/');
        let text = code(&path);
        let refs = out.entry(module.clone()).or_default();
        for (i, _) in text.match_indices("crate::") {
            let name: String = text[i + 7..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            refs.insert(name);
        }
        // `super::x` in a top-level file is the crate root's x.
        if !nested {
            for (i, _) in text.match_indices("super::") {
                let name: String = text[i + 7..]
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                refs.insert(name);
            }
        }
        refs.remove(&module);
    }
    let known: BTreeSet<&str> = LAYERS.iter().map(|l| l.0).collect();
    for refs in out.values_mut() {
        refs.retain(|r| known.contains(r.as_str()));
    }
    out
}

#[test]
fn every_module_imports_only_from_its_layer_or_below() {
    let layer: BTreeMap<&str, u8> = LAYERS.into_iter().collect();
    let imports = imports();
    assert_eq!(
        imports.keys().map(String::as_str).collect::<BTreeSet<_>>(),
        layer.keys().copied().collect::<BTreeSet<_>>(),
        "every top-level module has a layer here and in docs/layout.md"
    );
    let mut up = Vec::new();
    for (module, refs) in &imports {
        for r in refs {
            if layer[r.as_str()] > layer[module.as_str()] {
                up.push(format!("{module} → {r}"));
            }
        }
    }
    assert!(up.is_empty(), "imports from a higher layer: {up:?}");
}

/// The modules of `imports` (module → the modules it refers to) that lie on a circle: those in
/// their own reach.
fn on_circles(imports: &BTreeMap<String, BTreeSet<String>>) -> Vec<String> {
    let mut circles = Vec::new();
    for start in imports.keys() {
        let mut seen = BTreeSet::new();
        let mut todo: Vec<&String> = imports[start].iter().collect();
        while let Some(m) = todo.pop() {
            if seen.insert(m.clone()) {
                todo.extend(imports.get(m).into_iter().flatten());
            }
        }
        if seen.contains(start) {
            circles.push(start.clone());
        }
    }
    circles
}

#[test]
fn no_two_modules_import_each_other() {
    let circles = on_circles(&imports());
    assert!(circles.is_empty(), "modules on an import circle: {circles:?}");
}

/// The library speaks of configuration fields; flags are the command line's words (its table in
/// `cli/fields.rs`). A `--flag` in library code is allowed only inside a `bitrock …` command
/// the message tells the user to run; `clap` only behind the `cli` feature.
#[test]
fn the_library_names_no_flag_and_needs_no_clap() {
    let mut found = Vec::new();
    for (rel, path) in library_files() {
        for (i, line) in code(&path).lines().enumerate() {
            let flag = line
                .match_indices("--")
                .any(|(at, _)| line[at + 2..].starts_with(|c: char| c.is_ascii_lowercase()));
            if flag && !line.contains("bitrock ") {
                found.push(format!("src/{rel}:{}: {}", i + 1, line.trim()));
            }
            if line.contains("clap::") && !line.contains("cfg_attr(feature = \"cli\"") {
                found.push(format!("src/{rel}:{}: {}", i + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "command-line words in the library:\n{}",
        found.join("\n")
    );
}

/// The layout table (docs/layout.md) names every module in its layer's row: the map a
/// newcomer reads stays the one the imports follow.
#[test]
fn the_layout_table_matches_the_layers() {
    const ROWS: [&str; 7] = ["ground", "physics", "scoring", "samplers", "runs", "reports", "watch"];
    let layout = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/layout.md")).unwrap();
    let row = |name: &str| -> String {
        layout
            .lines()
            .find(|l| l.starts_with(&format!("| {name} |")))
            .unwrap_or_else(|| panic!("the layout table has no `{name}` row"))
            .to_string()
    };
    let mut misplaced = Vec::new();
    for (module, layer) in LAYERS {
        let line = row(ROWS[layer as usize]);
        if !line.contains(&format!("`{module}.rs`")) && !line.contains(&format!("`{module}/`")) {
            misplaced.push(format!("{module} (layer {})", ROWS[layer as usize]));
        }
    }
    assert!(misplaced.is_empty(), "modules not in their layout row: {misplaced:?}");
}

/// Inside a room (a folder of the library), module → the sibling modules it refers to:
/// `super::x` and `super::{x, …}` in a file of the folder, and `crate::room::x` anywhere in it.
/// The room's own file (`mod.rs`, or `shard.rs` for `shard/`) is its front door (shared types,
/// re-exports) and not a sibling.
fn sibling_imports() -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
    let mut rooms: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    let files = library_files();
    for (rel, _) in &files {
        if let Some((room, file)) = rel.rsplit_once('/')
            && file != "mod.rs"
        {
            let name = file.trim_end_matches(".rs").to_string();
            rooms.entry(room.to_string()).or_default().entry(name).or_default();
        }
    }
    // A sub-folder is a sibling too (`abc/shard/` is `shard`).
    let folders: Vec<String> = rooms.keys().cloned().collect();
    for folder in folders {
        if let Some((room, name)) = folder.rsplit_once('/') {
            rooms
                .entry(room.to_string())
                .or_default()
                .entry(name.to_string())
                .or_default();
        }
    }
    let path_name = |text: &str| -> Vec<String> {
        // After `super::`: one name, or a `{…}` group's first segments.
        if let Some(group) = text.strip_prefix('{') {
            let inner = &group[..group.find('}').unwrap_or(group.len())];
            inner
                .split(',')
                .map(|s| s.trim().split("::").next().unwrap().trim().to_string())
                .collect()
        } else {
            vec![
                text.chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect(),
            ]
        }
    };
    for (rel, path) in &files {
        let Some((room, file)) = rel.rsplit_once('/') else {
            continue;
        };
        if file == "mod.rs" {
            continue;
        }
        let me = file.trim_end_matches(".rs").to_string();
        let text = code(path);
        let siblings = rooms[room].keys().cloned().collect::<BTreeSet<_>>();
        let mut refs = BTreeSet::new();
        for (i, _) in text.match_indices("super::") {
            refs.extend(path_name(&text[i + 7..]));
        }
        let prefix = format!("crate::{}::", room.replace('/', "::"));
        for (i, _) in text.match_indices(&prefix) {
            refs.extend(path_name(&text[i + prefix.len()..]));
        }
        refs.retain(|r| siblings.contains(r) && *r != me);
        rooms.get_mut(room).unwrap().insert(me, refs);
    }
    rooms
}

/// No circle between the modules of one room either: a sampler, a kernel's host or a part of a
/// run can be read, changed and tested from its own file and the ones below it.
#[test]
fn no_two_modules_of_a_room_import_each_other() {
    let circles: Vec<String> = sibling_imports()
        .iter()
        .flat_map(|(room, imports)| on_circles(imports).into_iter().map(move |m| format!("{room}/{m}")))
        .collect();
    assert!(
        circles.is_empty(),
        "modules on an import circle inside their room: {circles:?}"
    );
}
