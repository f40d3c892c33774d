//! Fuzzing of the model reader and of `--set`: the example model files, mutated (bytes
//! changed, lines deleted or repeated, tokens swapped, numbers replaced by extremes such as
//! 1e308, -0, 5e-324, nan or inf, strings replaced by huge ones) and overridden with random
//! key paths and values. Properties: reading never panics; every error carries its location
//! (`FILE:LINE:COL` first in its message) and a bounded message; a model that reads is
//! accepted or refused by the solver's set-up (`Simulation::new`, `Statics::new`) without a
//! panic.
//!
//! A short run with a fixed seed is part of `cargo test`; a longer one:
//!
//! ```sh
//! FLEXMB_FUZZ_CASES=100000 cargo test --release -p flexmb --test input fuzz_model_reader
//! ```
//!
//! (`FLEXMB_FUZZ_SEED=<integer>` changes the seed; a failure prints the smallest input found.)

use crate::common;

use flexmb::input::{parse_model_str, Analysis, InputError};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};

/// The example files mutated (the long chains are left out to keep a case fast).
const EXAMPLES: &[&str] = &[
    "heavy_top.toml",
    "heavy_top_r3so3.toml",
    "pendulum.toml",
    "four_bar.toml",
    "andrews.toml",
    "bricard.toml",
    "chain_10.toml",
    "roll_up.toml",
    "bend_45.toml",
    "lee_frame.toml",
    "right_angle_cantilever.toml",
    "spin_up.toml",
    "flexible_four_bar.toml",
    "slider_crank.toml",
];

const EXTREMES: &[&str] = &[
    "1e308",
    "-1e308",
    "1e400",
    "-0",
    "-0.0",
    "0",
    "5e-324",
    "1e-320",
    "2.5e-13",
    "1e-30",
    "1e30",
    "1e9",
    "1e12",
    "nan",
    "inf",
    "-inf",
    "9223372036854775807",
    "-9223372036854775808",
    "-1",
    "[1e308, 0, 0]",
    "[]",
    "{}",
];

const KEYS: &[&str] = &[
    "solver.h",
    "solver.t_end",
    "solver.h_min",
    "solver.output_interval",
    "solver.rho_inf",
    "solver.arc_length",
    "solver.increment",
    "solver.min_increment",
    "solver.max_increment",
    "solver.load_factor",
    "solver.max_iterations",
    "solver.method",
    "solver.scheme",
    "model.gravity.1",
    "model.group",
    "body.0.mass",
    "body.0.inertia",
    "body.0.com",
    "body.0.orientation",
    "body.0.position",
    "node.0.position",
    "joint.0.axis",
    "joint.0.position",
    "joint.0.node_b",
    "joint.0.drive",
    "load.0.force",
    "load.0.function",
    "spring.0.rest_length",
    "sensor.0.name",
    "sensor.0.component",
    "beam.0.elements",
    "beam.0.end",
    "beam.0.section.EA",
    "beam.0.orientation",
    "nosuch.key",
    "body.nosuch.mass",
    "solver..h",
    "",
];

const VALUES: &[&str] = &[
    "{ rotation_vector = [1e200, 0, 0] }",
    "{ axis = [1, 0, 0], angle_deg = 1e308 }",
    "{ type = \"sine\", amplitude = 1, frequency = 1e300 }",
    "{ type = \"ramp\", t0 = 0, t1 = 5e-324, value = 1 }",
    "\"time\"",
    "\"a,b\"",
    "ground",
    "R3xSO3",
    "arc_length",
    "pseudo_dynamic",
    "newmark",
    "[",
    "{",
    "\"\"",
    "=",
];

#[derive(Clone, Debug)]
enum Mutation {
    /// Replace the byte at a position (a fraction of the length, in 1/2^16).
    Byte(u16, u8),
    DeleteLine(u16),
    RepeatLine(u16),
    SwapTokens(u16, u16),
    /// Replace the k-th number with an extreme.
    Number(u16, usize),
    /// Replace the k-th quoted string with a huge one.
    HugeString(u16),
}

fn at(fraction: u16, len: usize) -> usize {
    (fraction as usize * len) >> 16
}

/// Byte ranges of the numbers (outside strings) and of the quoted strings of `text`.
fn spans(text: &str, strings: bool) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'"' {
            let end = b[i + 1..].iter().position(|&c| c == b'"' || c == b'\n');
            let end = end.map_or(b.len(), |e| i + 1 + e);
            if strings {
                out.push((i + 1, end));
            }
            i = end + 1;
        } else if b[i] == b'#' {
            i += b[i..]
                .iter()
                .position(|&c| c == b'\n')
                .unwrap_or(b.len() - i);
        } else if !strings && (b[i].is_ascii_digit() || b[i] == b'-') {
            let end = b[i..]
                .iter()
                .position(|c| !(c.is_ascii_alphanumeric() || b".-+_".contains(c)))
                .map_or(b.len(), |e| i + e);
            out.push((i, end));
            i = end;
        } else {
            i += 1;
        }
    }
    out
}

fn mutate(text: &str, mutations: &[Mutation]) -> String {
    let mut s = text.to_string();
    for m in mutations {
        match *m {
            Mutation::Byte(p, byte) => {
                let mut bytes = s.into_bytes();
                if !bytes.is_empty() {
                    let i = at(p, bytes.len());
                    bytes[i] = byte;
                }
                s = String::from_utf8_lossy(&bytes).into_owned();
            }
            Mutation::DeleteLine(p) | Mutation::RepeatLine(p) => {
                let mut lines: Vec<&str> = s.lines().collect();
                if !lines.is_empty() {
                    let i = at(p, lines.len());
                    if matches!(m, Mutation::DeleteLine(_)) {
                        lines.remove(i);
                    } else {
                        lines.insert(i, lines[i]);
                    }
                }
                s = lines.join("\n");
            }
            Mutation::SwapTokens(p, q) => {
                let mut tokens: Vec<&str> = s.split(' ').collect();
                let (i, j) = (at(p, tokens.len()), at(q, tokens.len()));
                tokens.swap(i, j);
                s = tokens.join(" ");
            }
            Mutation::Number(p, k) => {
                let numbers = spans(&s, false);
                if !numbers.is_empty() {
                    let (a, b) = numbers[at(p, numbers.len())];
                    s.replace_range(a..b, EXTREMES[k % EXTREMES.len()]);
                }
            }
            Mutation::HugeString(p) => {
                let strings = spans(&s, true);
                if !strings.is_empty() {
                    let (a, b) = strings[at(p, strings.len())];
                    s.replace_range(a..b, &"x".repeat(100_000));
                }
            }
        }
    }
    s
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<u16>(), any::<u8>()).prop_map(|(p, b)| Mutation::Byte(p, b)),
        (
            any::<u16>(),
            prop::sample::select(b"0-.e[]{}=\"',\n axyz_".to_vec())
        )
            .prop_map(|(p, b)| Mutation::Byte(p, b)),
        any::<u16>().prop_map(Mutation::DeleteLine),
        any::<u16>().prop_map(Mutation::RepeatLine),
        (any::<u16>(), any::<u16>()).prop_map(|(p, q)| Mutation::SwapTokens(p, q)),
        (any::<u16>(), any::<usize>()).prop_map(|(p, k)| Mutation::Number(p, k)),
        (any::<u16>(), any::<usize>()).prop_map(|(p, k)| Mutation::Number(p, k)),
        any::<u16>().prop_map(Mutation::HugeString),
    ]
}

/// A `--set` string: a key path and a value, each known or random.
fn override_text() -> impl Strategy<Value = String> {
    let key = prop_oneof![
        3 => prop::sample::select(KEYS).prop_map(str::to_string),
        1 => "[a-z_.0-9]{0,24}",
    ];
    let value = prop_oneof![
        prop::sample::select(EXTREMES).prop_map(str::to_string),
        prop::sample::select(VALUES).prop_map(str::to_string),
        "[ -~]{0,16}",
    ];
    prop_oneof![
        9 => (key.clone(), value).prop_map(|(k, v)| format!("{k}={v}")),
        1 => key,
    ]
}

fn examples() -> Vec<(String, String)> {
    EXAMPLES
        .iter()
        .map(|name| {
            let text = std::fs::read_to_string(common::example(name)).unwrap();
            (name.to_string(), text)
        })
        .collect()
}

/// The properties for one input.
fn check(name: &str, text: &str, overrides: &[String]) -> Result<(), TestCaseError> {
    match parse_model_str(text, name, overrides) {
        Err(e) => {
            let message = e.to_string();
            let location = e.location().expect("only reading a file has no location");
            prop_assert!(
                message.starts_with(&format!("{location}: ")),
                "unlocated: {message}"
            );
            prop_assert!(message.len() < 3000, "{} bytes", message.len());
            if let InputError::Field { field, .. } | InputError::Override { field, .. } = &e {
                prop_assert!(message.contains(&format!("field '{field}'")), "{message}");
            }
        }
        Ok(file) => match file.analysis {
            Analysis::Dynamic(settings) => {
                let _ = flexmb::Simulation::new(&file.model, settings);
            }
            Analysis::Static(settings) => {
                let _ = flexmb::solve::Statics::new(&file.model, settings);
            }
        },
    }
    Ok(())
}

fn env_number(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn runner(default_cases: u32) -> TestRunner {
    let cases = env_number("FLEXMB_FUZZ_CASES", default_cases as u64) as u32;
    let seed = env_number("FLEXMB_FUZZ_SEED", 0x5eed_f1e3);
    let mut bytes = [0u8; 32];
    bytes[..8].copy_from_slice(&seed.to_le_bytes());
    let config = Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    };
    TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &bytes))
}

#[test]
fn mutated_example_files_and_overrides_give_located_errors_or_models_never_panics() {
    let files = examples();
    let strategy = (
        0..files.len(),
        prop::collection::vec(mutation(), 0..3),
        prop::collection::vec(override_text(), 0..2),
    );
    runner(2000)
        .run(&strategy, |(i, mutations, overrides)| {
            let (name, text) = &files[i];
            check(name, &mutate(text, &mutations), &overrides)
        })
        .unwrap();
}

#[test]
fn random_overrides_of_every_example_give_located_errors_or_models_never_panics() {
    let files = examples();
    let strategy = (0..files.len(), prop::collection::vec(override_text(), 1..3));
    runner(1000)
        .run(&strategy, |(i, overrides)| {
            let (name, text) = &files[i];
            check(name, text, &overrides)
        })
        .unwrap();
}
