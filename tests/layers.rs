//! The workspace's layering, checked on its source: no file-level import cycle inside any crate's
//! library (`data`, `model`, `train`, `eval`, `sim`), and nothing under `sim/src/task/` reaches the
//! engine, the world or the pack (directly or through others).
//!
//! Every path a file names is collected — `use` trees (grouped `{a::b, c}`, `self`, `as`, globs),
//! and paths written inline in code (`crate::x::y`, `super::super::z`, `child_module::item`) — and
//! resolved to the file that defines the item, following `use`/`pub use` re-exports (so
//! `crate::mujoco::Data`, re-exported from `engine::mujoco`, lands on `engine/mujoco/mod.rs`). Comments
//! and string literals are skipped. `#[cfg(test)]` modules are left out: nothing imports a test
//! module, so it cannot sit on a cycle of the library, and unit tests may drive the whole stack.
//! A binary (`main.rs`, `cli/`, `bin/`) is another crate, reaching its library only by name.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A module path (`["world", "scene", "arena"]`; empty for the crate root).
type ModPath = Vec<String>;

/// One source file of the library.
struct File {
    /// Its module path.
    module: ModPath,
    /// Relative path from `src/`, for messages.
    rel: String,
    /// Code with comments, strings and `#[cfg(test)]` modules removed.
    code: String,
    /// Names bound by its `use` declarations: name → absolute target path.
    imports: BTreeMap<String, ModPath>,
    /// Absolute paths of its glob imports (`use x::*`).
    globs: Vec<ModPath>,
}

/// The crates whose libraries are checked.
const CRATES: [&str; 5] = ["data", "model", "train", "eval", "sim"];

fn src_dir(krate: &str) -> PathBuf {
    e2e::repo_root().join(krate).join("src")
}

fn rs_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rs_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `world/scene/mod.rs` → `world::scene`; `lib.rs` → root; `task/goal.rs` → `task::goal`.
fn module_of(rel: &Path) -> ModPath {
    let mut parts: Vec<String> = rel
        .iter()
        .map(|s| s.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts
}

/// The code of `src` without comments, with every string/char literal emptied.
fn strip(src: &str) -> String {
    let b: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        let next = b.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < b.len() && b[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
            out.push(' ');
        } else if (c == 'r' || c == 'b')
            && !b
                .get(i.wrapping_sub(1))
                .is_some_and(|p| p.is_alphanumeric() || *p == '_')
            && raw_string_start(&b, i).is_some()
        {
            let (hashes, body) = raw_string_start(&b, i).unwrap();
            let mut j = body;
            loop {
                if j >= b.len() {
                    break;
                }
                if b[j] == '"' && (0..hashes).all(|k| b.get(j + 1 + k) == Some(&'#')) {
                    j += 1 + hashes;
                    break;
                }
                j += 1;
            }
            out.push_str("\"\"");
            i = j;
        } else if c == '"' {
            i += 1;
            while i < b.len() && b[i] != '"' {
                if b[i] == '\\' {
                    i += 1;
                }
                i += 1;
            }
            i += 1;
            out.push_str("\"\"");
        } else if c == '\'' {
            // A char literal ('x', '\n', '\u{..}') or a lifetime ('a).
            if next == Some('\\') {
                let mut j = i + 2;
                while j < b.len() && b[j] != '\'' {
                    j += 1;
                }
                i = j + 1;
                out.push_str("' '");
            } else if b.get(i + 2) == Some(&'\'') {
                i += 3;
                out.push_str("' '");
            } else {
                out.push(c);
                i += 1;
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// At `i`, `r"`, `r#"`, `br"`…: (number of `#`, index after the opening quote).
fn raw_string_start(b: &[char], i: usize) -> Option<(usize, usize)> {
    let mut j = i;
    if b[j] == 'b' {
        j += 1;
    }
    if b.get(j) != Some(&'r') {
        return None;
    }
    j += 1;
    let mut hashes = 0;
    while b.get(j) == Some(&'#') {
        hashes += 1;
        j += 1;
    }
    (b.get(j) == Some(&'"')).then_some((hashes, j + 1))
}

/// `code` without the bodies of `#[cfg(test)]` items (test modules, test-only functions).
fn drop_cfg_test(code: &str) -> String {
    let mut out = String::new();
    let mut rest = code;
    while let Some(k) = rest.find("#[cfg(test)]") {
        out.push_str(&rest[..k]);
        let after = &rest[k..];
        // The item ends at its first `;` before any `{`, or at the `}` closing its first `{`.
        let bytes = after.as_bytes();
        let mut depth = 0usize;
        let mut end = after.len();
        for (j, &ch) in bytes.iter().enumerate().skip("#[cfg(test)]".len()) {
            match ch {
                b'{' => depth += 1,
                b'}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = j + 1;
                        break;
                    }
                }
                b';' if depth == 0 => {
                    end = j + 1;
                    break;
                }
                _ => {}
            }
        }
        rest = &after[end..];
    }
    out.push_str(rest);
    out
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// The `use` declarations of `code`: each one's tree text (between `use` and `;`).
fn use_trees(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    let chars: Vec<(usize, char)> = code.char_indices().collect();
    for (n, &(k, _)) in chars.iter().enumerate() {
        if !code[k..].starts_with("use") {
            continue;
        }
        let before = n.checked_sub(1).map(|m| chars[m].1);
        let after = code[k + 3..].chars().next();
        if before.is_some_and(is_ident) || !after.is_some_and(char::is_whitespace) {
            continue;
        }
        let Some(end) = code[k..].find(';') else {
            continue;
        };
        out.push(code[k + 3..k + end].trim().to_string());
    }
    out
}

/// Expands a use tree (`crate::a::{b, c::{d as e, self}, f::*}`) into (bound name, path) pairs;
/// a glob binds `*`.
fn expand_tree(tree: &str) -> Vec<(String, Vec<String>)> {
    fn go(prefix: &[String], t: &str, out: &mut Vec<(String, Vec<String>)>) {
        let t = t.trim();
        if t.is_empty() {
            return;
        }
        // Split off a leading `a::b::` prefix up to a group or the end.
        if let Some(open) = t.find('{')
            && !t[..open].contains(',')
        {
            let head: Vec<String> = t[..open]
                .split("::")
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty())
                .collect();
            let close = t.rfind('}').unwrap();
            let mut p = prefix.to_vec();
            p.extend(head);
            for part in split_top(&t[open + 1..close]) {
                go(&p, part, out);
            }
            return;
        }
        let (path, alias) = match t.split_once(" as ") {
            Some((p, a)) => (p.trim(), Some(a.trim().to_string())),
            None => (t, None),
        };
        let mut p = prefix.to_vec();
        p.extend(path.split("::").map(|s| s.trim().to_string()));
        if p.last().is_some_and(|l| l == "self") {
            p.pop();
        }
        let name = alias.unwrap_or_else(|| p.last().cloned().unwrap_or_default());
        out.push((name, p));
    }
    let mut out = Vec::new();
    go(&[], tree, &mut out);
    out
}

/// Splits `a, b::{c, d}, e` at its top-level commas.
fn split_top(s: &str) -> Vec<&str> {
    let (mut depth, mut start, mut out) = (0, 0, Vec::new());
    for (k, c) in s.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                out.push(&s[start..k]);
                start = k + 1;
            }
            _ => {}
        }
    }
    out.push(&s[start..]);
    out
}

/// Paths written in code outside `use`: `crate::…`, `super::…`, `self::…` and `name::…` with `name`
/// a child module of `module`.
fn inline_paths(code: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let chars: Vec<char> = code.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        if !is_ident(chars[i]) || (i > 0 && (is_ident(chars[i - 1]) || chars[i - 1] == ':')) {
            i += 1;
            continue;
        }
        let mut segs = Vec::new();
        let mut j = i;
        loop {
            let s = j;
            while j < chars.len() && is_ident(chars[j]) {
                j += 1;
            }
            segs.push(chars[s..j].iter().collect::<String>());
            if chars.get(j) == Some(&':')
                && chars.get(j + 1) == Some(&':')
                && chars.get(j + 2).is_some_and(|c| is_ident(*c))
            {
                j += 2;
            } else {
                break;
            }
        }
        if segs.len() > 1 {
            out.push(segs);
        }
        i = j.max(i + 1);
    }
    out
}

/// A path as written in the file of `module` → absolute, or `None` for other crates and locals.
fn absolute(
    module: &ModPath,
    path: &[String],
    modules: &BTreeSet<ModPath>,
    imports: &BTreeMap<String, ModPath>,
) -> Option<ModPath> {
    let first = path.first()?;
    match first.as_str() {
        "crate" => Some(path[1..].to_vec()),
        "self" => {
            let mut m = module.clone();
            m.extend(path[1..].iter().cloned());
            Some(m)
        }
        "super" => {
            let mut m = module.clone();
            let mut k = 0;
            while path.get(k).is_some_and(|s| s == "super") {
                m.pop()?;
                k += 1;
            }
            m.extend(path[k..].iter().cloned());
            Some(m)
        }
        name => {
            let mut child = module.clone();
            child.push(name.to_string());
            if modules.contains(&child) {
                child.extend(path[1..].iter().cloned());
                Some(child)
            } else if let Some(target) = imports.get(name) {
                let mut m = target.clone();
                m.extend(path[1..].iter().cloned());
                Some(m)
            } else {
                None
            }
        }
    }
}

/// The file (index) defining the item at absolute `path`, following re-exports.
fn resolve(path: &[String], files: &[File], by_module: &BTreeMap<ModPath, usize>) -> Option<usize> {
    let mut path = path.to_vec();
    'restart: for _ in 0..32 {
        let mut m: ModPath = Vec::new();
        for (k, seg) in path.iter().enumerate() {
            let f = &files[by_module[&m]];
            let mut child = m.clone();
            child.push(seg.clone());
            // A last segment naming both a child module and an item of this file (`bddl::parse`,
            // the function, next to `mod parse`) is the item: `use` would import the public one.
            let last = k + 1 == path.len();
            if by_module.contains_key(&child) && !(last && defines(&f.code, seg)) {
                m = child;
                continue;
            }
            if let Some(target) = f.imports.get(seg) {
                let mut p = target.clone();
                p.extend(path[k + 1..].iter().cloned());
                path = p;
                continue 'restart;
            }
            return Some(by_module[&m]);
        }
        return by_module.get(&m).copied();
    }
    None
}

/// Whether `code` defines an item named `name` (fn, struct, enum, trait, type, const, static).
fn defines(code: &str, name: &str) -> bool {
    ["fn", "struct", "enum", "trait", "type", "const", "static"]
        .iter()
        .any(|kw| {
            code.match_indices(&format!("{kw} {name}")).any(|(k, m)| {
                let before = code[..k].chars().next_back();
                let after = code[k + m.len()..].chars().next();
                !before.is_some_and(is_ident) && !after.is_some_and(is_ident)
            })
        })
}

struct Graph {
    files: Vec<File>,
    /// Edges: file → (file it names, an example path naming it).
    edges: Vec<BTreeMap<usize, String>>,
}

fn graph(krate: &str) -> Graph {
    let src = src_dir(krate);
    let mut paths = Vec::new();
    rs_files(&src, &mut paths);
    paths.sort();
    let sources = paths
        .iter()
        .map(|p| {
            let rel = p
                .strip_prefix(&src)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            (rel, std::fs::read_to_string(p).unwrap())
        })
        .filter(|(rel, _)| rel != "main.rs" && !rel.starts_with("cli/") && !rel.starts_with("bin/"))
        .collect();
    graph_of(sources)
}

/// The file graph of sources given as (path under `src/`, text).
fn graph_of(sources: Vec<(String, String)>) -> Graph {
    let mut files: Vec<File> = sources
        .into_iter()
        .map(|(rel, text)| File {
            module: module_of(Path::new(&rel)),
            rel,
            code: drop_cfg_test(&strip(&text)),
            imports: BTreeMap::new(),
            globs: Vec::new(),
        })
        .collect();
    let modules: BTreeSet<ModPath> = files.iter().map(|f| f.module.clone()).collect();
    let by_module: BTreeMap<ModPath, usize> = files
        .iter()
        .enumerate()
        .map(|(k, f)| (f.module.clone(), k))
        .collect();
    // Imports first (a path in code may start with an imported name).
    for f in files.iter_mut() {
        for tree in use_trees(&f.code) {
            for (name, path) in expand_tree(&tree) {
                let Some(abs) = absolute(&f.module, &path, &modules, &BTreeMap::new()) else {
                    continue;
                };
                if name == "*" {
                    let mut g = abs;
                    g.pop();
                    f.globs.push(g);
                } else {
                    f.imports.insert(name, abs);
                }
            }
        }
    }
    let mut edges = vec![BTreeMap::new(); files.len()];
    for (k, f) in files.iter().enumerate() {
        let mut named: Vec<ModPath> = f.imports.values().cloned().collect();
        named.extend(f.globs.iter().cloned());
        for p in inline_paths(&f.code) {
            if let Some(abs) = absolute(&f.module, &p, &modules, &BTreeMap::new()) {
                named.push(abs);
            }
        }
        for abs in named {
            if let Some(t) = resolve(&abs, &files, &by_module)
                && t != k
            {
                edges[k].entry(t).or_insert_with(|| abs.join("::"));
            }
        }
    }
    Graph { files, edges }
}

/// Files reachable from `start` (itself excluded unless on a cycle).
fn reachable(g: &Graph, start: usize) -> BTreeSet<usize> {
    let mut seen = BTreeSet::new();
    let mut stack: Vec<usize> = g.edges[start].keys().copied().collect();
    while let Some(n) = stack.pop() {
        if seen.insert(n) {
            stack.extend(g.edges[n].keys().copied());
        }
    }
    seen
}

/// A path from `from` to `to` in the graph, as file names with the path that makes each step.
fn route(g: &Graph, from: usize, to: usize) -> Vec<String> {
    let mut prev: BTreeMap<usize, usize> = BTreeMap::new();
    let mut queue = std::collections::VecDeque::from([from]);
    let mut seen = BTreeSet::from([from]);
    while let Some(n) = queue.pop_front() {
        for &m in g.edges[n].keys() {
            if m == to {
                let mut steps = vec![format!(
                    "{} --{}--> {}",
                    g.files[n].rel, g.edges[n][&m], g.files[m].rel
                )];
                let mut c = n;
                while c != from {
                    let p = prev[&c];
                    steps.push(format!(
                        "{} --{}--> {}",
                        g.files[p].rel, g.edges[p][&c], g.files[c].rel
                    ));
                    c = p;
                }
                steps.reverse();
                return steps;
            }
            if seen.insert(m) {
                prev.insert(m, n);
                queue.push_back(m);
            }
        }
    }
    Vec::new()
}

#[test]
fn no_file_level_import_cycle_in_any_crate() {
    let mut found = Vec::new();
    for krate in CRATES {
        let g = graph(krate);
        assert!(
            g.files.len() >= 4,
            "{krate}: found only {} files",
            g.files.len()
        );
        found.extend(cycles(&g).into_iter().map(|c| format!("{krate}: {c}")));
    }
    assert!(
        found.is_empty(),
        "file-level import cycles:\n{}",
        found.join("\n")
    );
}

/// The detector on a made-up crate: a cycle through a re-export and an inline path is found; a
/// test module's import is not an edge.
#[test]
fn detector_finds_a_cycle_through_reexports_and_inline_paths() {
    let src = |rel: &str, text: &str| (rel.to_string(), text.to_string());
    let g = graph_of(vec![
        src(
            "lib.rs",
            "pub mod a;\npub mod b;\npub mod c;\npub use a::Thing;",
        ),
        src("a/mod.rs", "pub struct Thing;\nfn f() { crate::b::g(); }"),
        src(
            "b.rs",
            "pub fn g() {}\n#[cfg(test)]\nmod tests { use crate::c::*; }",
        ),
        src(
            "c.rs",
            "use crate::{b, Thing};\npub fn h(_: Thing) { b::g(); }",
        ),
    ]);
    assert!(cycles(&g).is_empty(), "{:?}", cycles(&g));
    let g = graph_of(vec![
        src("lib.rs", "pub mod a;\npub mod b;\npub use a::Thing;"),
        src("a/mod.rs", "pub struct Thing;\nfn f() { crate::b::g(); }"),
        src(
            "b.rs",
            "use crate::{Thing as T};\npub fn g(_: Option<T>) {}",
        ),
    ]);
    let found = cycles(&g);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(
        found[0].contains("a/mod.rs") && found[0].contains("b.rs"),
        "{found:?}"
    );
}

/// One message per strongly connected component of more than one file.
fn cycles(g: &Graph) -> Vec<String> {
    let reach: Vec<BTreeSet<usize>> = (0..g.files.len()).map(|k| reachable(g, k)).collect();
    let mut cycles = Vec::new();
    let mut reported = BTreeSet::new();
    for k in 0..g.files.len() {
        if !reach[k].contains(&k) || reported.contains(&k) {
            continue;
        }
        // k's strongly connected component: the files on some cycle with it.
        let component: Vec<usize> = (0..g.files.len())
            .filter(|&j| reach[k].contains(&j) && reach[j].contains(&k))
            .collect();
        reported.extend(component.iter().copied());
        let names: Vec<&str> = component.iter().map(|&j| g.files[j].rel.as_str()).collect();
        cycles.push(format!(
            "cycle among [{}], e.g.\n  {}",
            names.join(", "),
            route(g, k, k).join("\n  ")
        ));
    }
    cycles
}

#[test]
fn task_reaches_no_engine_world_or_pack() {
    let g = graph("sim");
    let forbidden = |rel: &str| {
        ["engine/", "world/", "pack/"]
            .iter()
            .any(|d| rel.starts_with(d))
    };
    let mut bad = Vec::new();
    let task: Vec<usize> = (0..g.files.len())
        .filter(|&k| g.files[k].rel.starts_with("task/"))
        .collect();
    assert!(task.len() >= 5, "task files: {}", task.len());
    for &k in &task {
        for t in reachable(&g, k) {
            if forbidden(&g.files[t].rel) {
                bad.push(route(&g, k, t).join("\n  "));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "task/ reaches lower-level layers:\n{}",
        bad.join("\n")
    );
}

/// The parser itself, on the forms the crate uses.
#[test]
fn parser_reads_grouped_super_inline_and_ignores_comments_and_strings() {
    let code = strip(
        r##"
//! Doc: crate::commented::Out
use crate::{a::b, c::{d as e, self}, f::*};
pub(crate) use super::super::g::H;
use std::fmt;
fn x() { let s = "crate::in_string::X"; let r = r#"crate::raw::Y"#; crate::inline::z(); super::up::w(); let c = '"'; }
/* crate::block::Comment */
#[cfg(test)]
mod tests { use crate::only_tests::T; }
"##,
    );
    let code = drop_cfg_test(&code);
    let mut uses: Vec<Vec<String>> = use_trees(&code)
        .iter()
        .flat_map(|t| expand_tree(t))
        .map(|(_, p)| p)
        .collect();
    uses.sort();
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    assert_eq!(
        uses,
        vec![
            s(&["crate", "a", "b"]),
            s(&["crate", "c"]),
            s(&["crate", "c", "d"]),
            s(&["crate", "f", "*"]),
            s(&["std", "fmt"]),
            s(&["super", "super", "g", "H"]),
        ]
    );
    let inline: Vec<String> = inline_paths(&code).iter().map(|p| p.join("::")).collect();
    assert!(
        inline.contains(&"crate::inline::z".to_string()),
        "{inline:?}"
    );
    assert!(inline.contains(&"super::up::w".to_string()), "{inline:?}");
    for gone in ["commented", "in_string", "raw", "block", "only_tests"] {
        assert!(!code.contains(gone), "{gone} survived: {code}");
    }
    let m = s(&["world", "scene", "place"]);
    let modules = BTreeSet::from([s(&["world", "scene", "place", "inner"])]);
    assert_eq!(
        absolute(
            &m,
            &s(&["super", "super", "env", "Env"]),
            &modules,
            &BTreeMap::new()
        ),
        Some(s(&["world", "env", "Env"]))
    );
    assert_eq!(
        absolute(&m, &s(&["inner", "f"]), &modules, &BTreeMap::new()),
        Some(s(&["world", "scene", "place", "inner", "f"]))
    );
}

/// `LAYERS_PRINT=sim cargo test -p e2e --test layers -- --nocapture` prints a crate's file graph.
#[test]
fn print_graph_when_asked() {
    let Some(krate) = std::env::var_os("LAYERS_PRINT") else {
        return;
    };
    let g = graph(&krate.to_string_lossy());
    for (k, f) in g.files.iter().enumerate() {
        let to: Vec<&str> = g.edges[k]
            .keys()
            .map(|&t| g.files[t].rel.as_str())
            .collect();
        println!("{} -> {}", f.rel, to.join(", "));
    }
}
