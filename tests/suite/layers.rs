//! The layer rules of docs/architecture.md, read from the source: every `crate::`, `super::`
//! and `self::` path in the library's crates (comments and test modules left out) is an arrow
//! from the module that writes it to the module it names. An arrow must point to a lower
//! layer of [`LAYERS`], and no modules at any depth may import each other round a cycle.
//!
//! Between crates the compiler holds the order: the core crate cannot name the daemon's
//! modules at all. What this file checks is the order inside each crate, and that each
//! module sits in the crate its layer belongs to.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The library's top-level modules, lowest layer first. A module may use the modules of the
/// layers below its own, never those of its own layer or above. The binaries (`src/main.rs`,
/// `src/cli/`, `src/bin/`) sit above them all.
const LAYERS: &[&[&str]] = &[
    &["time", "secret", "geodesy", "sources"],
    &["devices", "fusion", "broker"],
    &["ntrip", "control", "zones"],
    &["config"],
    &["vehicle"],
    &["record", "api"],
    &["engine"],
    &["sim"],
    &["interchange"],
    &["runtime"],
    &["replay"],
    &["calib"],
    &["bench"],
];

/// The library's crates, each with the top-level modules it holds, lowest first: the core
/// (`crates/core`, sans-IO) holds the layers up to the engine, and the daemon's library (`src`)
/// re-exports them under the same names and adds the rest.
const CRATES: &[(&str, &[&str])] = &[
    (
        "crates/core/src",
        &[
            "time", "secret", "geodesy", "sources", "devices", "fusion", "broker", "ntrip",
            "control", "zones", "config", "vehicle", "record", "api", "engine",
        ],
    ),
    (
        "src",
        &["sim", "interchange", "runtime", "replay", "calib", "bench"],
    ),
];

type ModulePath = Vec<String>;

/// One arrow: the writing module, the named module, and where it is written.
struct Import {
    from: ModulePath,
    to: ModulePath,
    at: String,
}

#[test]
fn every_import_points_down_the_layers() {
    let rank = |module: &str| LAYERS.iter().position(|layer| layer.contains(&module));
    let imports = library_imports();
    let mut wrong = Vec::new();
    let mut unplaced = BTreeSet::new();
    for import in &imports {
        let (from, to) = (&import.from[0], &import.to[0]);
        if from == to {
            continue;
        }
        match (rank(from), rank(to)) {
            (Some(f), Some(t)) if t < f => {}
            (Some(_), Some(_)) => wrong.push(format!("{from} -> {to} at {}", import.at)),
            (None, _) => drop(unplaced.insert(from.clone())),
            (_, None) => drop(unplaced.insert(to.clone())),
        }
    }
    assert!(
        unplaced.is_empty(),
        "modules in no layer of LAYERS (place them there and in docs/architecture.md): {unplaced:?}"
    );
    assert!(
        wrong.is_empty(),
        "imports against the layer order (a module may only use lower layers):\n{}",
        wrong.join("\n")
    );
}

#[test]
fn each_module_lives_in_the_crate_of_its_layer() {
    let mut wrong = Vec::new();
    for (root, modules) in CRATES {
        let src = repo().join(root);
        for module in *modules {
            let dir = src.join(module);
            if !dir.is_dir() && !dir.with_extension("rs").is_file() {
                wrong.push(format!("{module} is not in {root}"));
            }
        }
        for entry in std::fs::read_dir(&src).expect("readable crate") {
            let path = entry.expect("directory entry").path();
            let name = path.file_stem().unwrap_or_default().to_string_lossy();
            let placed = modules.contains(&name.as_ref());
            if !placed && !matches!(name.as_ref(), "lib" | "main" | "cli" | "bin") {
                wrong.push(format!("{root}/{name} is in no crate of CRATES"));
            }
        }
    }
    // The crates' order is the layers' order: no layer of the core above one of the daemon.
    let order: Vec<&str> = CRATES.iter().flat_map(|(_, m)| m.iter().copied()).collect();
    let rank = |module: &str| LAYERS.iter().position(|layer| layer.contains(&module));
    for pair in order.windows(2) {
        if rank(pair[0]) > rank(pair[1]) {
            wrong.push(format!("{} sits above {} in LAYERS", pair[0], pair[1]));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn the_core_crate_has_no_async_runtime() {
    // The core is sans-IO: the daemon brings tokio, sockets and clocks.
    let manifest = std::fs::read_to_string(repo().join("crates/core/Cargo.toml"))
        .expect("the core's manifest");
    let manifest: toml::Table = toml::from_str(&manifest).expect("the core's manifest is TOML");
    let dependencies = manifest["dependencies"]
        .as_table()
        .expect("a [dependencies] table");
    for runtime in ["tokio", "async-std", "smol", "mio"] {
        assert!(
            !dependencies.contains_key(runtime),
            "the core depends on {runtime}"
        );
    }
    // No dependency may switch on its own async support either, in the core's manifest or
    // in the workspace's shared entry it takes.
    let root: toml::Table = toml::from_str(
        &std::fs::read_to_string(repo().join("Cargo.toml")).expect("the root manifest"),
    )
    .expect("the root manifest is TOML");
    let shared = &root["workspace"]["dependencies"];
    for (name, spec) in dependencies {
        let own = spec.get("features").and_then(toml::Value::as_array);
        let from_workspace = spec
            .get("workspace")
            .and_then(|_| shared.get(name))
            .and_then(|s| s.get("features"))
            .and_then(toml::Value::as_array);
        for feature in own.into_iter().chain(from_workspace).flatten() {
            let feature = feature.as_str().unwrap_or_default();
            assert!(
                !feature.contains("tokio") && !feature.contains("async"),
                "the core takes {name} with its {feature} feature"
            );
        }
    }
    assert!(
        dependencies.contains_key("socketcan"),
        "the core's CAN frames and candump logs come from socketcan: the check above read nothing"
    );
}

#[test]
fn no_modules_import_each_other_round_a_cycle() {
    let imports = library_imports();
    let deepest = imports.iter().map(|i| i.from.len()).max().unwrap_or(1);
    let mut cycles = Vec::new();
    // At each depth, modules are their paths cut to that many names; an arrow between a
    // module and its own parent or child is how Rust nests modules, not a dependency.
    for depth in 1..=deepest {
        let mut graph: BTreeMap<ModulePath, BTreeSet<ModulePath>> = BTreeMap::new();
        for import in &imports {
            let from = cut(&import.from, depth);
            let to = cut(&import.to, depth);
            if !from.starts_with(&to) && !to.starts_with(&from) {
                graph.entry(from).or_default().insert(to);
            }
        }
        cycles.extend(find_cycle(&graph).map(|c| c.join(" -> ")));
    }
    assert!(cycles.is_empty(), "import cycles:\n{}", cycles.join("\n"));
}

/// The modules that turn requests into commands and results into protocol codes.
const DECIDING_MODULES: &[&str] = &["api", "engine", "vehicle", "control"];

/// The text searches these modules may make, each on a client's input and never on a reason
/// or a reply: a trajectory name may not climb out of its folder.
const ALLOWED_TEXT_SEARCHES: &[&str] = &["name.contains(\"..\")"];

#[test]
fn no_code_is_chosen_by_searching_text() {
    // A protocol code chosen by searching a reason's words changes when the words do; the
    // reasons are enums (control::outcome, vehicle::safety) to be matched instead.
    let mut searches = Vec::new();
    for module in DECIDING_MODULES {
        let mut files = Vec::new();
        collect_rs_files(&module_dir(module), &mut files);
        for file in files {
            let text = std::fs::read_to_string(&file).expect("readable source");
            let library = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
            for (n, line) in without_comments(library).lines().enumerate() {
                let searching = [
                    ".contains(\"",
                    ".starts_with(\"",
                    ".ends_with(\"",
                    ".find(\"",
                ]
                .iter()
                .any(|s| line.contains(s));
                if searching && !ALLOWED_TEXT_SEARCHES.iter().any(|a| line.contains(a)) {
                    let shown = file.strip_prefix(repo()).unwrap_or(&file);
                    searches.push(format!("{}:{}: {}", shown.display(), n + 1, line.trim()));
                }
            }
        }
    }
    assert!(
        searches.is_empty(),
        "text searched where a code may be chosen (match on a typed reason instead):\n{}",
        searches.join("\n")
    );
}

#[test]
fn the_engine_routes_records_by_a_lookup_not_by_comparing_names() {
    // Each source's route is resolved once, when the engine is built (engine::Route).
    let mut files = Vec::new();
    collect_rs_files(&module_dir("engine"), &mut files);
    let mut compared = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).expect("readable source");
        let library = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
        for (n, line) in without_comments(library).lines().enumerate() {
            if line.contains("source ==") || line.contains("source !=") {
                compared.push(format!("{}:{}: {}", file.display(), n + 1, line.trim()));
            }
        }
    }
    assert!(
        compared.is_empty(),
        "records routed by name:\n{}",
        compared.join("\n")
    );
}

/// The ROS protocols' adapters and links: their requests reach the core typed, through
/// their own adapter, never re-encoded as the local channel's JSON (`api::legacy` reads
/// recordings made before, when they were).
const ROS_ADAPTERS: &[&[&str]] = &[
    &["api", "ros1"],
    &["api", "rosbridge"],
    &["runtime", "links", "ros1"],
    &["runtime", "links", "websocket"],
];

#[test]
fn ros_adapters_do_not_speak_the_local_channel() {
    let within = |path: &ModulePath, prefix: &[&str]| {
        path.len() >= prefix.len() && path.iter().zip(prefix).all(|(a, b)| a == b)
    };
    let imports = library_imports();
    assert!(
        imports
            .iter()
            .any(|i| within(&i.from, &["api", "ros1"]) && within(&i.to, &["api", "requests"])),
        "the ROS1 adapter's own requests are not found: the reader reads nothing"
    );
    let found: Vec<&str> = imports
        .iter()
        .filter(|i| ROS_ADAPTERS.iter().any(|a| within(&i.from, a)))
        .filter(|i| within(&i.to, &["api", "local"]))
        .map(|i| i.at.as_str())
        .collect();
    assert!(
        found.is_empty(),
        "a ROS adapter speaks the local channel:\n{}",
        found.join("\n")
    );
}

/// The one place in the library that may name `anyhow`: roslibrust's service callbacks
/// answer with its `ServiceError`, which is `anyhow::Error`.
const ANYHOW_ALLOWED: &[&str] = &["runtime/links/ros1/graph.rs"];

#[test]
fn anyhow_stays_at_the_binarys_edge() {
    let mut found = Vec::new();
    for (src, relative, file) in library_files() {
        let shown = relative.display().to_string();
        if module_of(&relative).is_none() || ANYHOW_ALLOWED.contains(&shown.as_str()) {
            continue;
        }
        let text = std::fs::read_to_string(&file).expect("readable source");
        let library = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
        for (n, line) in without_comments(library).lines().enumerate() {
            if line.contains("anyhow") {
                found.push(format!("{src}/{shown}:{}: {}", n + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "anyhow in the library (give the module a thiserror enum):\n{}",
        found.join("\n")
    );
}

#[test]
fn the_reader_finds_the_arrows_it_is_meant_to() {
    // The parser's own check, on lines of known meaning, so the rules above cannot pass by
    // reading nothing.
    let here: ModulePath = vec!["api".into(), "ros1".into(), "status".into()];
    let found = |code: &str| {
        let mut out = Vec::new();
        arrows_in(&without_comments(code), &here, &mut out);
        out.iter().map(|(_, p)| p.join("::")).collect::<Vec<_>>()
    };
    assert_eq!(
        found("use crate::vehicle::status::Navigation;"),
        ["vehicle::status::Navigation"]
    );
    assert_eq!(
        found("use super::super::mqtt::Publish;"),
        ["api::mqtt::Publish"]
    );
    assert_eq!(
        found("let x = self::inner::f();"),
        ["api::ros1::status::inner::f"]
    );
    assert_eq!(
        found("let u = \"ntrip://user@host\"; // crate::nothing"),
        Vec::<String>::new()
    );
    assert_eq!(found("/// see [`crate::engine`]"), Vec::<String>::new());
    assert_eq!(
        found("use super::{\n    chassis::{Chassis, self},\n    Safety,\n};"),
        [
            "api::ros1::chassis::Chassis",
            "api::ros1::chassis",
            "api::ros1::Safety"
        ]
    );
    assert_eq!(
        found("x = crate::config::motion::creep(1.0)"),
        ["config::motion::creep"]
    );
    assert!(
        library_imports().len() > 500,
        "the source tree was not read"
    );
}

/// The first cycle in `graph`, as the module names round it.
fn find_cycle(graph: &BTreeMap<ModulePath, BTreeSet<ModulePath>>) -> Option<Vec<String>> {
    fn visit(
        node: &ModulePath,
        graph: &BTreeMap<ModulePath, BTreeSet<ModulePath>>,
        done: &mut BTreeSet<ModulePath>,
        stack: &mut Vec<ModulePath>,
    ) -> Option<Vec<String>> {
        if let Some(start) = stack.iter().position(|n| n == node) {
            let mut cycle: Vec<String> = stack[start..].iter().map(|n| n.join("::")).collect();
            cycle.push(node.join("::"));
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        stack.push(node.clone());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(cycle) = visit(next, graph, done, stack) {
                return Some(cycle);
            }
        }
        stack.pop();
        done.insert(node.clone());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|node| visit(node, graph, &mut done, &mut Vec::new()))
}

fn cut(path: &ModulePath, depth: usize) -> ModulePath {
    path[..depth.min(path.len())].to_vec()
}

/// Every arrow written in the library's source, each named module cut to the module files
/// that exist (a path's tail is an item, not a module).
fn library_imports() -> Vec<Import> {
    let mut imports = Vec::new();
    for (src, relative, file) in library_files() {
        let Some(from) = module_of(&relative) else {
            continue; // the binary's own files
        };
        let text = std::fs::read_to_string(&file).expect("readable source");
        // Unit tests may reach anywhere to build their fixtures; the library may not.
        let library = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
        let code = without_comments(library);
        let mut named = Vec::new();
        arrows_in(&code, &from, &mut named);
        for (offset, path) in named {
            let to = existing_module(&path);
            if !to.is_empty() {
                let line = code[..offset].matches('\n').count() + 1;
                imports.push(Import {
                    from: from.clone(),
                    to,
                    at: format!("{src}/{}:{line}", relative.display()),
                });
            }
        }
    }
    imports
}

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every Rust file of the library's crates: its crate's source folder (as written in
/// [`CRATES`]), its path under that folder, and its full path.
fn library_files() -> Vec<(&'static str, std::path::PathBuf, std::path::PathBuf)> {
    let mut out = Vec::new();
    for (src, _) in CRATES {
        let root = repo().join(src);
        let mut files = Vec::new();
        collect_rs_files(&root, &mut files);
        for file in files {
            let relative = file
                .strip_prefix(&root)
                .expect("under its crate")
                .to_path_buf();
            out.push((*src, relative, file));
        }
    }
    out
}

/// The folder (or file, without `.rs`) of a top-level module, in whichever crate holds it.
fn module_dir(module: &str) -> std::path::PathBuf {
    CRATES
        .iter()
        .map(|(src, _)| repo().join(src).join(module))
        .find(|p| p.is_dir() || p.with_extension("rs").is_file())
        .unwrap_or_else(|| panic!("no crate holds the module {module}"))
}

fn collect_rs_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("readable src") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            collect_rs_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module a file under `src/` defines; `None` for the binary's files.
fn module_of(relative: &Path) -> Option<ModulePath> {
    let mut parts: ModulePath = relative
        .with_extension("")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if matches!(parts[0].as_str(), "main" | "cli" | "bin") {
        return None;
    }
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    Some(parts)
}

/// The longest prefix of `path` that is a module file or folder in one of the crates.
fn existing_module(path: &[String]) -> ModulePath {
    let mut keep = 0;
    for n in 1..=path.len() {
        let exists = CRATES.iter().any(|(src, _)| {
            let base = repo().join(src).join(path[..n].join("/"));
            base.is_dir() || base.with_extension("rs").is_file()
        });
        if exists {
            keep = n;
        } else {
            break;
        }
    }
    path[..keep].to_vec()
}

/// The absolute paths of the `crate::`, `super::` and `self::` paths in `code` (comments
/// already removed), written in module `here`, each with the byte offset it starts at. A
/// brace group (`use super::{a::X, b}`), on one line or several, gives a path per item.
fn arrows_in(code: &str, here: &ModulePath, out: &mut Vec<(usize, ModulePath)>) {
    let bytes = code.as_bytes();
    let mut at = 0;
    while at < code.len() {
        let word_start = at == 0 || !is_ident(bytes[at - 1]) && bytes[at - 1] != b':';
        let anchor = ["crate::", "super::", "self::"]
            .into_iter()
            .find(|a| word_start && bytes[at..].starts_with(a.as_bytes()));
        let Some(anchor) = anchor else {
            at += 1;
            continue;
        };
        // The anchor is ASCII, so `at` is a character boundary here.
        let rest = &code[at..];
        let mut base = match anchor {
            "crate::" => Vec::new(),
            "super::" => here[..here.len().saturating_sub(1)].to_vec(),
            _ => here.clone(),
        };
        let mut tail = &rest[anchor.len()..];
        while let Some(next) = tail.strip_prefix("super::") {
            base.pop();
            tail = next;
        }
        let mut paths = Vec::new();
        use_tree(tail, base, &mut paths);
        out.extend(paths.into_iter().map(|p| (at, p)));
        at += anchor.len();
    }
}

/// Reads one path (or brace group of paths) from the start of `text`, under `prefix`.
/// Returns how many bytes it read.
fn use_tree(text: &str, mut prefix: ModulePath, out: &mut Vec<ModulePath>) -> usize {
    let mut at = 0;
    let mut read_a_name = false;
    loop {
        let rest = &text[at..];
        let skipped = rest.len() - rest.trim_start().len();
        at += skipped;
        let rest = &text[at..];
        if let Some(group) = rest.strip_prefix('{') {
            at += 1;
            let mut inner = group;
            loop {
                let read = use_tree(inner, prefix.clone(), out);
                at += read;
                inner = &inner[read..];
                let trimmed = inner.trim_start();
                at += inner.len() - trimmed.len();
                inner = trimmed;
                match inner.as_bytes().first() {
                    Some(b',') => {
                        at += 1;
                        inner = &inner[1..];
                    }
                    Some(b'}') => return at + 1,
                    _ => return at,
                }
            }
        }
        let name: String = rest
            .chars()
            .take_while(|c| c.is_ascii() && is_ident(*c as u8))
            .collect();
        if name.is_empty() {
            break;
        }
        at += name.len();
        read_a_name = true;
        if name != "self" {
            prefix.push(name);
        }
        match text[at..].strip_prefix("::") {
            Some(_) => at += 2,
            None => break,
        }
    }
    if read_a_name && !prefix.is_empty() {
        out.push(prefix);
    }
    at
}

/// `text` with its line comments removed (doc comments too). A `//` inside a string ends
/// that line early, which can only miss an arrow, never invent one.
fn without_comments(text: &str) -> String {
    text.lines()
        .map(|line| line.find("//").map_or(line, |at| &line[..at]))
        .collect::<Vec<_>>()
        .join("\n")
}

fn is_ident(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_'
}
