//! The daemon's modules import one way: `config` at the bottom, `compute` and `capture` above it, the
//! pipeline stages above both, the servers (`http`, `dbus`, `rtsp`) on top. A circle (capture taking
//! the camera factory from the pipeline, config validating through the pipeline's `Live`)
//! makes every module a dependency of every other; this keeps it from coming back. The engine's
//! and the simulator's module rules of ARCHITECTURE.md are checked here too (one parser).

use std::path::{Path, PathBuf};

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            sources(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// A module's files: `src/NAME.rs` where it exists and everything under `src/NAME/`.
fn module_files(src: &Path, name: &str) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = Some(src.join(format!("{name}.rs")))
        .filter(|f| f.exists())
        .into_iter()
        .collect();
    if src.join(name).is_dir() {
        sources(&src.join(name), &mut files);
    }
    files
}

#[test]
fn module_arrows_run_one_way() {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    // (module, the modules above it that it must not name)
    let rules: [(&str, &[&str]); 4] = [
        (
            "config",
            &[
                "compute", "capture", "pipeline", "http", "dbus", "notify", "rtsp",
            ],
        ),
        // The compute backend (the adapter opened at start) sits on config.
        (
            "compute",
            &["capture", "pipeline", "http", "dbus", "notify", "rtsp"],
        ),
        ("capture", &["pipeline", "http", "dbus", "notify", "rtsp"]),
        ("pipeline", &["http", "dbus", "rtsp"]),
    ];
    let mut checked = 0;
    for (module, above) in rules {
        for f in &module_files(&src, module) {
            let text = std::fs::read_to_string(f).unwrap();
            // A doc link may name any module; grouped imports (`crate::{a, b::C}`) count.
            let code = code_of(&text);
            let top = f.parent() == Some(src.as_path());
            let named = named_paths(&code, top);
            for up in above {
                let head_is = |p: &String| p.split("::").next() == Some(*up);
                assert!(
                    !named.iter().any(head_is) && !code.contains(&format!("volcapd::{up}")),
                    "{} names {up}: {module} must not depend on {up}",
                    f.display()
                );
            }
            checked += 1;
        }
    }
    assert!(
        checked >= 8,
        "only {checked} files checked: did the modules move?"
    );
}

/// The engine's and the simulator's rules of ARCHITECTURE.md, checked on their code: comments
/// and `#[cfg(test)]` items left out (a doc link or a test may name any module), the paths
/// behind `crate::` (and a top-level file's `super::`) expanded through `{...}` groups.
#[test]
fn engine_and_simulator_modules_keep_their_rules() {
    let service = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("service/daemon has a parent")
        .to_path_buf();
    // (module: its file and folder under src; the module paths it must not name; `*`: any but `allowed`)
    type Rule<'a> = (&'a str, &'a [&'a str], &'a [&'a str]);
    let engine: &[Rule] = &[
        ("grid", &["*"], &[]),
        ("softz", &["*"], &[]),
        ("sides", &["*"], &["grid"]),
        (
            "field",
            &["localize", "render", "mesh", "metrics", "pieces"],
            &[],
        ),
        ("analytic", &["localize", "render", "mesh", "metrics"], &[]),
        ("localize", &["render", "mesh", "metrics", "pieces"], &[]),
        ("render", &["mesh", "metrics"], &[]),
        ("mesh", &["render", "localize"], &[]),
        ("pieces", &["render", "field", "localize", "model"], &[]),
        ("metrics", &["localize", "render"], &[]),
        (
            "gpu",
            &["model::runtime", "model::net", "model::threads"],
            &[],
        ),
    ];
    let sim: &[Rule] = &[
        ("scene", &["raster", "sim"], &[]),
        ("effects", &["raster", "sim"], &[]),
        // The oracle shares the texture type with the rasterizer, nothing that draws.
        (
            "oracle",
            &[
                "raster::Rasterizer",
                "raster::Framebuffer",
                "raster::DrawMesh",
                "sim",
            ],
            &[],
        ),
    ];
    let mut checked = 0;
    for (krate, rules) in [("engine", engine), ("sim", sim)] {
        let src = service.join(krate).join("src");
        for (at, forbidden, allowed) in rules {
            let files = module_files(&src, at);
            assert!(
                !files.is_empty(),
                "{krate}/src/{at}: no files (did the module move?)"
            );
            for f in &files {
                let text = std::fs::read_to_string(f).unwrap();
                let top = f.parent() == Some(src.as_path());
                for path in named_paths(&code_of(&text), top) {
                    let head = path.split("::").next().unwrap_or("");
                    // Items re-exported at the crate root (`crate::ISO`) are not modules.
                    if head.starts_with(|c: char| c.is_ascii_uppercase()) {
                        continue;
                    }
                    let bad = forbidden.iter().any(|m| {
                        (*m == "*" && !allowed.contains(&head))
                            || path == *m
                            || path.starts_with(&format!("{m}::"))
                    });
                    assert!(
                        !bad,
                        "{} names crate::{path}: ARCHITECTURE.md says {krate}/src/{at} must not \
                         depend on {forbidden:?}",
                        f.display()
                    );
                }
                checked += 1;
            }
        }
    }
    assert!(
        checked >= 25,
        "only {checked} files checked: did the modules move?"
    );

    // The crates themselves: no async runtime, server, bus or camera crate below the daemon,
    // and no sockets in their code.
    let below_the_daemon = [
        "tokio",
        "axum",
        "hyper",
        "zbus",
        "v4l",
        "sd-notify",
        "volcapd",
    ];
    for (krate, also) in [("engine", &["volcap-sim"][..]), ("sim", &[][..])] {
        let manifest = std::fs::read_to_string(service.join(krate).join("Cargo.toml")).unwrap();
        let deps = dependency_names(&manifest);
        assert!(
            deps.len() >= 5,
            "{krate}: {deps:?}: is the [dependencies] table read?"
        );
        for d in below_the_daemon.iter().chain(also) {
            assert!(
                !deps.iter().any(|x| x == d),
                "service/{krate}/Cargo.toml depends on {d}"
            );
        }
        let mut files = Vec::new();
        sources(&service.join(krate).join("src"), &mut files);
        for f in &files {
            let code = code_of(&std::fs::read_to_string(f).unwrap());
            for needle in ["std::net", "tokio::", "TcpStream", "UdpSocket"] {
                assert!(!code.contains(needle), "{} uses {needle}", f.display());
            }
        }
    }
}

/// The code of a Rust file without comments and without `#[cfg(test)]` items.
fn code_of(text: &str) -> String {
    let mut out = String::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        let t = line.trim();
        if t == "#[cfg(test)]" {
            // Skip further attributes, then the item: to its matching brace, or its `;`.
            let mut depth = 0i32;
            let mut opened = false;
            for l in lines.by_ref() {
                let l = strip_comment(l);
                if !opened && l.trim_start().starts_with("#[") {
                    continue;
                }
                for c in l.chars() {
                    match c {
                        '{' => {
                            depth += 1;
                            opened = true;
                        }
                        '}' => depth -= 1,
                        _ => {}
                    }
                }
                if (opened && depth <= 0) || (!opened && l.trim_end().ends_with(';')) {
                    break;
                }
            }
            continue;
        }
        out.push_str(strip_comment(line));
        out.push('\n');
    }
    out
}

fn strip_comment(line: &str) -> &str {
    if line.trim_start().starts_with("//") {
        return "";
    }
    match line.find(" // ") {
        Some(i) => &line[..i],
        None => line,
    }
}

/// Every path named after `crate::` (or, in a file at the top of `src`, `super::`), with
/// `{a, b::c}` groups expanded: `crate::model::{fourier::X, net}` gives `model::fourier::X`
/// and `model::net`.
fn named_paths(code: &str, top_level: bool) -> Vec<String> {
    let mut out = Vec::new();
    let mut roots = vec!["crate::"];
    if top_level {
        roots.push("super::");
    }
    for root in roots {
        let mut from = 0;
        while let Some(i) = code[from..].find(root) {
            let at = from + i;
            from = at + root.len();
            // `foo_crate::` or `bar.super::` is not the root.
            let before = code[..at].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                continue;
            }
            expand(&code[from..], String::new(), &mut out);
        }
    }
    out
}

fn expand(rest: &str, prefix: String, out: &mut Vec<String>) {
    let rest = rest.trim_start();
    if let Some(group) = rest.strip_prefix('{') {
        let mut depth = 0;
        let mut start = 0;
        for (i, c) in group.char_indices() {
            match c {
                '{' => depth += 1,
                '}' if depth == 0 => {
                    expand(&group[start..i], prefix.clone(), out);
                    return;
                }
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    expand(&group[start..i], prefix.clone(), out);
                    start = i + 1;
                }
                _ => {}
            }
        }
        return;
    }
    let end = rest
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(rest.len());
    if end == 0 {
        if !prefix.is_empty() {
            out.push(prefix);
        }
        return;
    }
    let path = if prefix.is_empty() {
        rest[..end].to_string()
    } else {
        format!("{prefix}::{}", &rest[..end])
    };
    match rest[end..].strip_prefix("::") {
        Some(more) => expand(more, path, out),
        None => out.push(path),
    }
}

/// The crate names of a manifest's `[dependencies]` table (not dev- or build-).
fn dependency_names(manifest: &str) -> Vec<String> {
    let mut names = Vec::new();
    let mut inside = false;
    for line in manifest.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            inside = t == "[dependencies]";
            continue;
        }
        if inside
            && !t.starts_with('#')
            && let Some(name) = t.split(['=', '.', ' ']).next().filter(|n| !n.is_empty())
        {
            names.push(name.to_string());
        }
    }
    names
}

#[test]
fn the_layering_parser_sees_what_it_must() {
    let code = code_of(
        "use crate::model::{fourier::{FourierMaps, SMOOTH_THIN}, net};\n\
         // crate::render in a comment\n\
         let x = crate::grid::offset(a); // crate::mesh\n\
         #[cfg(test)]\n\
         mod tests {\n    use crate::localize::X;\n    fn f() { let _ = 1; }\n}\n\
         #[cfg(test)]\nuse crate::pieces::Y;\n\
         fn after() -> super::field::F { todo!() }\n",
    );
    let mut got = named_paths(&code, true);
    got.sort();
    assert_eq!(
        got,
        [
            "field::F",
            "grid::offset",
            "model::fourier::FourierMaps",
            "model::fourier::SMOOTH_THIN",
            "model::net",
        ]
    );
    assert!(named_paths("my_crate::x", false).is_empty());
    let deps = dependency_names(
        "[package]\nname = \"a\"\n[dependencies]\nglam.workspace = true\n# tokio = 1\nwgpu = { version = \"30\" }\n[dev-dependencies]\nproptest = 1\n",
    );
    assert_eq!(deps, ["glam", "wgpu"]);
}
