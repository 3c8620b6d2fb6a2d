//! `embodied new` without a file system: which files, from which specs, with which
//! names. `tests/cli.rs` runs the binary, snapshots the files and builds them.

use super::generate::{File, NewError, Options, generate};
use super::*;

const TANK: &str = include_str!("../../../specs/tank.ron");

fn options(name: &str) -> Options {
    Options {
        name: name.into(),
        embodied_version: "0.1".into(),
        embodied_path: None,
    }
}

fn file<'a>(files: &'a [File], path: &str) -> &'a str {
    let found = files.iter().find(|f| f.path == path);
    found.map_or_else(|| panic!("no {path}"), |f| f.contents.as_str())
}

#[test]
fn a_crate_is_made_only_from_a_valid_spec_and_name() {
    let files = generate("tank.ron", TANK, &options("my-tank")).expect("a crate");
    let paths: Vec<&str> = files.iter().map(|f| f.path.as_str()).collect();
    for p in [
        "Cargo.toml",
        ".gitignore",
        "README.md",
        "spec.ron",
        "src/lib.rs",
        "src/main.rs",
        "src/types.rs",
        "src/logic.rs",
        "src/logic/c1.rs",
        "src/logic/c2.rs",
        "src/devices.rs",
        "src/system.rs",
        "tests/properties/main.rs",
        "tests/properties/c1.rs",
        "tests/properties/c2.rs",
        "tests/app.rs",
    ] {
        assert!(paths.contains(&p), "{p} in {paths:?}");
    }
    assert!(!paths.contains(&".cargo/config.toml"), "only when asked");
    assert_eq!(file(&files, "spec.ron"), TANK);
    assert!(
        file(&files, "Cargo.toml").contains(
            "\nembodied = { version = \"0.1\", features = [\"app\", \"distributed\"] }\n"
        )
    );
    // The program is the application layer; the tests launch the deployment
    // with the most processes, and kill one the spec lets be restarted.
    let main = file(&files, "src/main.rs");
    assert!(
        main.contains("App::new(\"spec.ron\", my_tank::system::SPEC)")
            && main.contains("my_tank::system::build_for(target.deployment())")
            && main.contains("// .ends_when(embodied::app::End::halted([\"c2\"]))"),
        "{main}"
    );
    let app = file(&files, "tests/app.rs");
    assert!(
        app.contains("\"split\"") && app.contains("\"operator@1.5\""),
        "the station may not be restarted (`restarts: 0`): {app}"
    );
    let types = file(&files, "src/types.rs");
    assert!(types.contains("pub struct Order;") && types.contains("pub struct StationParams;"));
    // The links come from the spec, not from a list in the code.
    let system = file(&files, "src/system.rs");
    assert!(system.contains("Assembly::all(&spec)"), "{system}");
    assert!(!system.contains("connect"), "{system}");
    assert!(
        system.contains("crate::devices::E1Driver::default()"),
        "{system}"
    );

    assert!(matches!(
        generate("t.ron", TANK, &options("My Tank")),
        Err(NewError::Name(_))
    ));
    let broken = TANK.replace("terminal: \"settled\"", "terminal: \"setled\"");
    assert!(matches!(
        generate("t.ron", &broken, &options("t")),
        Err(NewError::Spec(_))
    ));
}

#[test]
fn no_slot_is_left_unfilled_for_any_spec_of_the_repository() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut specs = Vec::new();
    for dir in ["specs", "tests/specs/valid"] {
        for entry in std::fs::read_dir(root.join(dir)).expect("the folder") {
            let path = entry.expect("an entry").path();
            if path.extension().is_some_and(|e| e == "ron") {
                specs.push(path);
            }
        }
    }
    assert!(specs.len() >= 4, "{specs:?}");
    for spec in specs {
        let source = std::fs::read_to_string(&spec).expect("the spec");
        let mut options = options("app");
        options.embodied_path = Some(PathBuf::from("/somewhere/embodied-agents"));
        let files = generate("spec.ron", &source, &options)
            .unwrap_or_else(|e| panic!("{}: {e}", spec.display()));
        for f in files.iter().filter(|f| f.path != "spec.ron") {
            assert!(
                !f.contents.contains("{{"),
                "{}: {}:\n{}",
                spec.display(),
                f.path,
                f.contents
            );
        }
    }
}

#[test]
fn names_that_would_clash_in_the_crate_are_refused() {
    let minimal = include_str!("../../../tests/specs/valid/minimal.ron");
    let taken = |text: &str, name: &str| match generate("m.ron", text, &options(name)) {
        Err(NewError::Taken { what, with, .. }) => format!("{what}: {with}"),
        other => panic!("{other:?}"),
    };
    let agent = minimal.replace("name: \"a2\"", "name: \"system\"");
    assert_eq!(taken(&agent, "app"), "agent: the crate's module `system`");
    let agent = minimal.replace("name: \"a2\"", "name: \"std\"");
    assert_eq!(taken(&agent, "app"), "agent: the crate `std`");
    // A subsystem's module stands beside `use proptest::...` in its test file, and
    // beside the tests' root.
    let sub = minimal
        .replace("\"c2", "\"proptest")
        .replace("c2.", "proptest.")
        .replace("peer: \"c2\"", "peer: \"proptest\"");
    assert_eq!(taken(&sub, "app"), "subsystem: the crate `proptest`");
    let sub = minimal
        .replace("\"c2", "\"main")
        .replace("c2.", "main.")
        .replace("peer: \"c2\"", "peer: \"main\"");
    assert_eq!(
        taken(&sub, "app"),
        "subsystem: the root of the tests, `tests/properties/main.rs`"
    );
    let sub = minimal
        .replace("\"c2", "\"mini_app")
        .replace("c2.", "mini_app.")
        .replace("peer: \"c2\"", "peer: \"mini_app\"");
    assert_eq!(taken(&sub, "mini-app"), "subsystem: the crate `mini_app`");
    for bad in ["Rex App", "serde", "type", "9lives", "-x", ""] {
        assert!(
            matches!(
                generate("m.ron", minimal, &options(bad)),
                Err(NewError::Name(_))
            ),
            "{bad:?}"
        );
    }
    // What the checker refuses, `new` refuses: a memory field named `self`.
    let keyword = minimal.replace(
        r#"(name: "count", type: "u32")"#,
        r#"(name: "self", type: "u32")"#,
    );
    assert!(matches!(
        generate("m.ron", &keyword, &options("app")),
        Err(NewError::Spec(_))
    ));
}

#[test]
fn a_checkout_is_patched_in_only_when_asked() {
    let mut options = options("app");
    options.embodied_path = Some(PathBuf::from(r#"/work/a "quoted" dir\x"#));
    let files = generate("tank.ron", TANK, &options).expect("a crate");
    let config = file(&files, ".cargo/config.toml");
    assert!(
        config.contains(
            "[patch.crates-io]\nembodied = { path = \"/work/a \\\"quoted\\\" dir\\\\x\" }\n"
        ),
        "{config}"
    );
    assert!(!file(&files, "Cargo.toml").contains("path"));
    assert_eq!(embodied_version(), "0.1");
}

#[test]
fn a_driver_is_made_with_default_and_has_room_for_state() {
    let files = generate("tank.ron", TANK, &options("app")).expect("a crate");
    let devices = file(&files, "src/devices.rs");
    assert!(
        devices.contains("#[derive(Debug, Default)]\npub struct E1Driver {}\n"),
        "{devices}"
    );
    // The termination tests: a reactive model per subsystem, a memory strategy per
    // behaviour that can end, and a verdict that knows the stubs.
    let c1 = file(&files, "tests/properties/c1.rs");
    assert!(c1.contains("impl Environment<C1> for World {"), "{c1}");
    for behaviour in ["idle", "fill", "settle", "report"] {
        assert!(c1.contains(&format!("fn memory_{behaviour}()")), "{c1}");
        assert!(c1.contains(&format!("fn {behaviour}_terminates()")), "{c1}");
    }
    assert!(file(&files, "tests/properties/main.rs").contains("fn verdict("));
}

#[test]
fn a_spec_without_a_deployment_gets_one_of_two_processes() {
    let minimal = include_str!("../../../tests/specs/valid/minimal.ron");
    let start = minimal
        .find("    deployments: [")
        .expect("minimal.ron has one");
    let end = start + minimal[start..].find("    ],\n").expect("its end") + "    ],\n".len();
    let without = format!("{}{}", &minimal[..start], &minimal[end..]);
    let files = generate("m.ron", &without, &options("app")).expect("a crate");
    let spec = file(&files, "spec.ron");
    assert!(
        spec.starts_with(without.trim_end().trim_end_matches(')').trim_end()),
        "{spec}"
    );
    assert!(
        spec.contains("name: \"local\"")
            && spec.contains("(name: \"a1\", runs: [\"c1\", \"e1\", \"E1\"]),")
            && spec.contains("(name: \"a2\", runs: [\"c2\"]),"),
        "one process per agent: {spec}"
    );
    let (parsed, report) = embodied::spec::check_source("spec.ron", spec.to_owned());
    assert!(report.is_ok(), "{}", report.short());
    assert_eq!(parsed.map(|s| s.deployments.len()), Some(1));
    assert!(file(&files, "tests/app.rs").contains("\"local\""));
    assert!(file(&files, "src/main.rs").contains("launch --deployment local"));
    // A spec with one: kept as given.
    let files = generate("m.ron", minimal, &options("app")).expect("a crate");
    assert_eq!(file(&files, "spec.ron"), minimal);
}
