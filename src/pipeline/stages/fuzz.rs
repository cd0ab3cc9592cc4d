//! Property-based fuzzing of the stage-file reader (test-only): structured mutations of the
//! stage files of a real chain (a 2-tet body through `tetrahedralize`, `solve`, `embed`).
//! Every mutated file must be rejected with a one-line error naming the file and a fix, or be
//! accepted and then run through the next stage without a panic: [`crate::pipeline::stage_file::read`]'s
//! validation is what keeps the stages from indexing out of range.
//!
//! `PROPTEST_CASES` sets the cases per stage type (default [`DEFAULT_CASES`]).

use std::path::Path;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};
use serde_json::Value;

use crate::algorithms::geometry::TetMesh;
use crate::pipeline::scene::{Method, Scene};
use crate::pipeline::stage_file::{self, Animation, Body, Keyframes, Outputs, Shape, Solution, StageData, VertexSet};
use crate::support::budget::Budget;
use crate::support::progress::Progress;

const DEFAULT_CASES: u32 = 1_000;

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|c| c.parse().ok()).unwrap_or(DEFAULT_CASES)
}

/// The chain's stage files, as JSON values.
fn seeds() -> (Value, Value, Value, Value) {
    let scene = Scene::parse("name = \"f\"\n[keyframes]\nmeshes = [\"a.mesh\", \"b.mesh\"]\ntimes = [0.0, 0.5]\n[solver]\nsamples = 3\n").unwrap();
    let mesh = TetMesh {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]],
        tets: vec![[0, 1, 2, 3], [0, 2, 1, 4]],
    };
    let moved: Vec<_> = mesh.positions.iter().map(|p| [p[0], p[1] + 0.5, p[2]]).collect();
    let keys = Keyframes {
        scene,
        rest_source: "a.mesh".into(),
        rest: Shape::Volume(mesh.clone()),
        times: vec![0.0, 0.5],
        poses: vec![mesh.positions.clone(), moved],
        fixed: vec![VertexSet::all(5), VertexSet::from_mask(&[true, false, true, false, false])],
        fixed_velocity: vec![VertexSet::default(), VertexSet::all(5)],
        cyclic: false,
        display: None,
        cache: None,
        input_bytes: 0,
        weld: None,
    };
    let progress = Progress::hidden();
    let body = crate::pipeline::stages::tetrahedralize(&keys, &Budget::default(), &progress).unwrap();
    let solution = crate::pipeline::stages::solve(&body, Some(Method::Hermite), &progress).unwrap();
    let animation = crate::pipeline::stages::embed(&solution).unwrap();
    let json = |bytes: Vec<u8>| serde_json::from_slice::<Value>(&bytes).unwrap();
    (json(stage_file::to_json(&keys)), json(stage_file::to_json(&body)), json(stage_file::to_json(&solution)), json(stage_file::to_json(&animation)))
}

/// JSON pointers of every node of `v`.
fn pointers(v: &Value, at: String, out: &mut Vec<String>) {
    match v {
        Value::Array(a) => a.iter().enumerate().for_each(|(i, x)| pointers(x, format!("{at}/{i}"), out)),
        Value::Object(o) => o.iter().for_each(|(k, x)| pointers(x, format!("{at}/{k}"), out)),
        _ => {}
    }
    out.push(at);
}

/// Values spliced in: index edges, signs, huge and tiny numbers, wrong types.
fn token(i: usize) -> Value {
    let tokens = [
        serde_json::json!(-1),
        serde_json::json!(0),
        serde_json::json!(1),
        serde_json::json!(2),
        serde_json::json!(4),
        serde_json::json!(5),
        serde_json::json!(100000),
        serde_json::json!(4294967295u32),
        serde_json::json!(0.5),
        serde_json::json!(-0.5),
        serde_json::json!(1e300),
        serde_json::json!(-1e300),
        serde_json::json!(1e-300),
        serde_json::json!(true),
        serde_json::json!("../x"),
        serde_json::json!(""),
        serde_json::json!([]),
        serde_json::json!(null),
    ];
    tokens[i % tokens.len()].clone()
}

/// Apply edits `(node, op, token)`: replace a node, pop or duplicate an array's last element,
/// swap two elements, remove an object key.
fn mutate(seed: &Value, edits: &[(prop::sample::Index, u8, usize)]) -> Value {
    let mut v = seed.clone();
    for (node, op, tok) in edits {
        let mut all = Vec::new();
        pointers(&v, String::new(), &mut all);
        let at = &all[node.index(all.len())];
        let Some(target) = v.pointer_mut(at) else { continue };
        match (op % 5, target) {
            (0, t) => *t = token(*tok),
            (1, Value::Array(a)) => {
                a.pop();
            }
            (2, Value::Array(a)) if !a.is_empty() => a.push(a[a.len() - 1].clone()),
            (3, Value::Array(a)) if a.len() >= 2 => {
                let j = tok % a.len();
                a.swap(0, j);
            }
            (4, Value::Object(o)) if !o.is_empty() => {
                let k = o.keys().nth(tok % o.len()).unwrap().clone();
                o.remove(&k);
            }
            (_, t) => *t = token(*tok),
        }
    }
    v
}

/// A mutated file is rejected by one line naming it, or accepted and `next` runs on it
/// (errors from `next` must be one line too; a panic fails the property).
fn check<T: StageData>(v: Value, next: impl Fn(&T) -> crate::support::error::Result<()>) -> Result<(), TestCaseError> {
    let bytes = serde_json::to_vec(&v).unwrap();
    let one_line = |e: crate::support::error::Error| -> Result<(), TestCaseError> {
        let s = e.with_path("f.json").to_string();
        prop_assert!(!s.chars().any(char::is_control) && s.starts_with("f.json: ") && s.contains(" (fix: ") && s.len() < 5000, "{s:?}");
        Ok(())
    };
    match stage_file::from_json::<T>(&bytes, Path::new("f.json"), &Budget::default()) {
        Err(e) => one_line(e),
        Ok(data) => match next(&data) {
            Err(e) => one_line(e),
            Ok(()) => Ok(()),
        },
    }
}

fn run(name: &str, seed: Value, property: impl Fn(Value) -> Result<(), TestCaseError>) {
    let strategy = prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), any::<usize>()), 1..4).prop_map(move |e| mutate(&seed, &e));
    let config = Config { cases: cases(), failure_persistence: None, max_shrink_iters: 500, ..Config::default() };
    TestRunner::new(config).run(&strategy, property).unwrap_or_else(|e| panic!("{name}: {e}"));
}

#[test]
fn mutated_stage_files_fail_cleanly_or_run() {
    let (keys, body, solution, animation) = seeds();
    let progress = Progress::hidden();
    run("keyframes", keys, |v| check::<Keyframes>(v, |k| crate::pipeline::stages::tetrahedralize(k, &Budget::default(), &progress).map(drop)));
    run("body", body, |v| check::<Body>(v, |b| crate::pipeline::stages::solve(b, Some(Method::Hermite), &progress).map(drop)));
    run("solution", solution, |v| check::<Solution>(v, |s| crate::pipeline::stages::embed(s).map(drop)));
    run("animation", animation, |v| {
        check::<Animation>(v, |a| crate::pipeline::stages::report(a, &Outputs { files: vec![], rank: None }, &Budget::default()).map(drop))
    });
}
