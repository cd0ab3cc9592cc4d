//! Property-based fuzzing of the input readers (test-only): OBJ, MEDIT, TetGen `.node`/`.ele`,
//! selection files (`.txt`, `.dmat`) and scene files, fed random bytes and random mutations of
//! valid files. Every input must give a result or a one-line error with a fix (never a panic),
//! within a time bound, allocating at most a bounded multiple of the input's size, and a
//! result must keep the reader's invariants (indices in range, tets positive, ...).
//!
//! `cargo test --lib fuzz` runs [`DEFAULT_CASES`] cases per property (tens of thousands in
//! all, a few seconds); `make fuzz` sets `PROPTEST_CASES` for a long run.
//!
//! Allocation is measured by the test binary's global allocator (`crate::support::testing::alloc`):
//! the peak of live bytes on the parsing thread during one parse.

use std::time::Instant;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

use crate::formats::mesh::{medit, obj, selection, tetgen_io};
use crate::pipeline::scene::Scene;
use crate::support::error::{Error, Result};
use crate::support::testing::alloc;

/// Cases per property unless `PROPTEST_CASES` says otherwise.
const DEFAULT_CASES: u32 = 10_000;
/// The most CPU time a single parse of a fuzz input (at most a few kilobytes) may take: the
/// parsing thread's own time ([`thread_cpu_seconds`]), not the wall clock, so the bound
/// catches a slow parse (quadratic work) without failing on a loaded machine that merely
/// leaves the thread waiting for a core.
const MAX_SECONDS: f64 = 1.0;
/// Peak allocation allowed for a parse: this many bytes per input byte, plus [`ALLOC_SLACK`].
const ALLOC_PER_BYTE: usize = 64;
const ALLOC_SLACK: usize = 1 << 20;

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|c| c.parse().ok()).unwrap_or(DEFAULT_CASES)
}

/// Run `property` over `strategy`; a failure panics with the (shrunk) input.
fn fuzz<S: Strategy>(name: &str, strategy: S, property: impl Fn(S::Value) -> Result<(), TestCaseError>)
where
    S::Value: std::fmt::Debug,
{
    let config = Config { cases: cases(), failure_persistence: None, max_shrink_iters: 2000, ..Config::default() };
    let started = Instant::now();
    PARSED.with(|p| p.set((0, 0)));
    WORST.with(|w| w.set(0.0));
    TestRunner::new(config).run(&strategy, property).unwrap_or_else(|e| panic!("{name}: {e}"));
    let (ok, all) = PARSED.with(std::cell::Cell::get);
    let worst = match WORST.with(std::cell::Cell::get) {
        0.0 => "no input of 1 KB or more".to_string(),
        w => format!("peak allocation up to {w:.1} bytes per input byte over inputs of 1 KB or more"),
    };
    eprintln!("fuzz {name}: {} cases, {ok} of {all} parses accepted, {worst}, in {:.2} s", cases(), started.elapsed().as_secs_f64());
}

/// CPU seconds the calling thread has used (`CLOCK_THREAD_CPUTIME_ID`).
fn thread_cpu_seconds() -> f64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec it is given and nothing else.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) } == 0;
    assert!(ok, "clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

thread_local! {
    /// Parses accepted and parses run by the current property (so a run shows it reached both
    /// the error paths and the invariants of accepted inputs).
    static PARSED: std::cell::Cell<(usize, usize)> = const { std::cell::Cell::new((0, 0)) };
    /// The largest peak allocation per input byte seen by the current property.
    static WORST: std::cell::Cell<f64> = const { std::cell::Cell::new(0.0) };
}

/// Parse `text` with `parse`, checking time, allocation and the shape of an error.
fn bounded<T>(text: &str, parse: impl FnOnce(&str) -> Result<T>) -> Result<Result<T>, TestCaseError> {
    let started = thread_cpu_seconds();
    let (result, peak) = alloc::peak(|| parse(text));
    let cpu = thread_cpu_seconds() - started;
    prop_assert!(cpu < MAX_SECONDS, "a parse of {} bytes took {cpu:.3} s of CPU", text.len());
    let bound = ALLOC_PER_BYTE * text.len() + ALLOC_SLACK;
    prop_assert!(peak <= bound, "a parse of {} bytes allocated {peak} bytes at once (bound {bound})", text.len());
    if text.len() >= 1024 {
        WORST.with(|w| w.set(w.get().max(peak as f64 / text.len() as f64)));
    }
    if let Err(e) = &result {
        check_message(e)?;
    }
    PARSED.with(|p| p.set((p.get().0 + usize::from(result.is_ok()), p.get().1 + 1)));
    Ok(result)
}

/// One line, with a problem and a fix, no control characters, and short.
fn check_message(e: &Error) -> Result<(), TestCaseError> {
    let s = e.clone().with_path("input").to_string();
    prop_assert!(!s.chars().any(char::is_control), "control character in {s:?}");
    prop_assert!(s.starts_with("input: ") && s.contains(" (fix: ") && s.ends_with(')'), "{s:?}");
    prop_assert!(!e.problem.is_empty() && !e.fix.is_empty(), "{s:?}");
    prop_assert!(s.len() < 5000, "a message of {} bytes", s.len());
    Ok(())
}

/// Tokens that readers treat specially, to splice into valid files.
const TOKENS: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "1e400",
    "-1",
    "0",
    "1",
    "2",
    "4294967296",
    "18446744073709551616",
    "99999999999999999999999",
    "0.5",
    "-0",
    "\u{feff}",
    "\n",
    "\r\n",
    "\r",
    "\t",
    " ",
    "#",
    "\u{0}",
    "\u{1b}[2J",
    "v",
    "f",
    "o",
    "g",
    "vt",
    "f 1 2 3",
    "f -1 -2 -3",
    "v 0 0 0",
    "1/2/3",
    "//",
    "MeshVersionFormatted",
    "Dimension",
    "Vertices",
    "Tetrahedra",
    "Triangles",
    "End",
    "1 3",
    "=",
    "[",
    "]",
    "{",
    "}",
    "\"",
    "name",
    "[keyframes]",
    "times",
    "meshes",
    "fixed",
    "axis",
    "min",
    "max",
    "samples",
    "gravity",
    "[material]",
    "é",
    "\u{202e}",
];

/// A mutation of a text: (where, what, how many, a token, a byte).
type Edit = (prop::sample::Index, u8, u8, prop::sample::Index, u8);

fn mutate(seed: &str, edits: &[Edit]) -> String {
    let mut bytes = seed.as_bytes().to_vec();
    for (at, op, len, token, byte) in edits {
        let at = at.index(bytes.len() + 1);
        let end = (at + *len as usize % 16).min(bytes.len());
        match op % 6 {
            0 => {
                bytes.drain(at..end);
            }
            1 => {
                let t = TOKENS[token.index(TOKENS.len())].as_bytes();
                bytes.splice(at..at, t.iter().copied());
            }
            2 => {
                let t = TOKENS[token.index(TOKENS.len())].as_bytes();
                bytes.splice(at..end, t.iter().copied());
            }
            3 => {
                if at < bytes.len() {
                    bytes[at] = *byte;
                }
            }
            4 => {
                // Duplicate the line at `at`.
                let start = bytes[..at].iter().rposition(|&b| b == b'\n').map_or(0, |p| p + 1);
                let stop = bytes[at..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |p| at + p + 1);
                let line = bytes[start..stop].to_vec();
                bytes.splice(stop..stop, line);
            }
            _ => {
                // A digit changed: counts and indices move by one or by a lot.
                if let Some(p) = bytes[at..].iter().position(u8::is_ascii_digit) {
                    bytes[at + p] = b'0' + byte % 10;
                }
            }
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

fn random_text() -> impl Strategy<Value = String> {
    prop_oneof![
        prop::collection::vec(any::<u8>(), 0..2048).prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
        // Printable ASCII with line breaks: closer to what the tokenizers see.
        prop::collection::vec(prop::sample::select(b" \n0123456789.-+eEvfo/#abcdefghijklmnopqrstuvwxyzVT[]{}=\"".to_vec()), 0..2048)
            .prop_map(|b| String::from_utf8(b).expect("ASCII")),
    ]
}

fn mutated(seed: &'static str) -> impl Strategy<Value = String> {
    prop::collection::vec(any::<Edit>(), 1..8).prop_map(move |edits| mutate(seed, &edits))
}

const OBJ: &str = "# cube\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\nvn 0 0 1\nvt 0 0\nvt 1 0\n\
                   f 1 3 2\nf 1 4 3\nf 5 6 7 8\nf 1/1/1 2/2/1 6//1\nf -8 -3 -7\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\no next\nv 9 9 9\n";
const MEDIT: &str = "MeshVersionFormatted 1\nDimension\n3\nVertices 5\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n0 0 -1 7\n\
                     Triangles\n1\n1 2 3 0\nTetrahedra\n2\n1 2 3 4 1\n1 2 3 5 1\nEnd\n";
const NODE: &str = "# nodes\n5 3 1 1\n1 0 0 0 9.5 1\n2 1 0 0 9.5 1\n3 0 1 0 9.5 1\n4 0 0 1 9.5 0\n5 0 0 -1 9.5 1\n";
const ELE: &str = "2 4 1\n1 1 2 3 4 7\n2 1 2 3 5 7\n";
const DMAT: &str = "1 6\n1\n0\n0\n1.0\n0\n1\n";
const INDICES: &str = "# held\n0\n5 # last\n\n3\n";
const SCENE: &str = r#"name = "twist"
fps = 60
[keyframes]
meshes = ["k0.obj", { mesh = "k0.obj", twist = { axis = "y", degrees = 90.0 } }, "k0.obj"]
times = [0.0, 0.5, 1.0]
fixed = ["all", [{ axis = "y", max = 0.1 }, "ends.txt"], { file = "tail.dmat", invert = true }]
cyclic = true
rest = 0
[tet]
quality = 1.414
[material]
stiffness = 70.0
gravity = [0.0, -9.8, 0.0]
[solver]
method = "spacetime"
samples = 10
[export]
formats = ["usda", "glb"]
"#;

fn check_obj(text: String) -> Result<(), TestCaseError> {
    if let Ok(mesh) = bounded(&text, obj::parse)? {
        prop_assert!(!mesh.triangles.is_empty());
        prop_assert!(mesh.triangles.iter().flatten().all(|&v| (v as usize) < mesh.positions.len()));
        prop_assert!(mesh.positions.iter().flatten().all(|x| x.is_finite()));
    }
    Ok(())
}

fn check_medit(text: String) -> Result<(), TestCaseError> {
    if let Ok(mesh) = bounded(&text, medit::parse)? {
        prop_assert!(!mesh.tets.is_empty());
        prop_assert!(mesh.tets.iter().flatten().all(|&v| (v as usize) < mesh.positions.len()));
        prop_assert!((0..mesh.tets.len()).all(|t| mesh.signed_volume_at(&mesh.positions, t) > 0.0));
    }
    Ok(())
}

fn check_tetgen((node, ele): (String, String)) -> Result<(), TestCaseError> {
    if let Ok((positions, first)) = bounded(&node, tetgen_io::parse_node)? {
        prop_assert!(first <= 1 && positions.iter().flatten().all(|x| x.is_finite()));
        if let Ok(tets) = bounded(&ele, |t| tetgen_io::parse_ele(t, first, positions.len()))? {
            prop_assert!(tets.iter().flatten().all(|&v| (v as usize) < positions.len()));
        }
    }
    Ok(())
}

fn check_selection((text, n): (String, usize)) -> Result<(), TestCaseError> {
    if let Ok(mask) = bounded(&text, |t| selection::parse_dmat(t, n))? {
        prop_assert_eq!(mask.len(), n);
    }
    if let Ok(mask) = bounded(&text, |t| selection::parse_indices(t, n))? {
        prop_assert_eq!(mask.len(), n);
    }
    Ok(())
}

fn check_scene(text: String) -> Result<(), TestCaseError> {
    if let Ok(scene) = bounded(&text, Scene::parse)? {
        // A valid scene survives the trip through a stage file.
        let json = serde_json::to_string(&scene).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let back: Scene = serde_json::from_str(&json).map_err(|e| TestCaseError::fail(format!("{e}: {json}")))?;
        prop_assert_eq!(back, scene);
    }
    Ok(())
}

#[test]
fn obj_reader() {
    fuzz("obj random", random_text(), check_obj);
    fuzz("obj mutated", mutated(OBJ), check_obj);
}

#[test]
fn medit_reader() {
    fuzz("medit random", random_text(), check_medit);
    fuzz("medit mutated", mutated(MEDIT), check_medit);
}

#[test]
fn tetgen_readers() {
    fuzz("tetgen random", (random_text(), random_text()), check_tetgen);
    fuzz("tetgen mutated", (mutated(NODE), mutated(ELE)), check_tetgen);
}

#[test]
fn selection_readers() {
    fuzz("selection random", (random_text(), 0..40usize), check_selection);
    fuzz("selection mutated", (prop_oneof![mutated(DMAT), mutated(INDICES)], 0..10usize), check_selection);
}

#[test]
fn scene_reader() {
    fuzz("scene random", random_text(), check_scene);
    fuzz("scene mutated", mutated(SCENE), check_scene);
}

/// Large valid files (about a megabyte each): the peak allocation of a parse stays a small
/// multiple of the file's size, far inside the bound the fuzzing checks.
#[test]
fn allocation_is_proportional_to_the_input() {
    let cube = crate::algorithms::testing::cube_mesh(30);
    let (points, tets) = (&cube.positions, &cube.tets);
    let mut medit_text = format!("MeshVersionFormatted 1\nDimension 3\nVertices {}\n", points.len());
    points.iter().for_each(|p| medit_text += &format!("{} {} {} 0\n", p[0], p[1], p[2]));
    medit_text += &format!("Tetrahedra {}\n", tets.len());
    tets.iter().for_each(|t| medit_text += &format!("{} {} {} {} 0\n", t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1));
    let mut node = format!("{} 3 0 0\n", points.len());
    points.iter().enumerate().for_each(|(i, p)| node += &format!("{i} {} {} {}\n", p[0], p[1], p[2]));
    let mut ele = format!("{} 4 0\n", tets.len());
    tets.iter().enumerate().for_each(|(i, t)| ele += &format!("{i} {} {} {} {}\n", t[0], t[1], t[2], t[3]));
    let obj_text = obj::write(&crate::algorithms::procedural::prism([1.0; 3], [60, 60, 60]));
    let v = points.len();
    let dmat = format!("1 {v}\n{}", "1\n0\n".repeat(v / 2) + if v % 2 == 1 { "1\n" } else { "" });
    let indices: String = (0..v).step_by(3).map(|i| format!("{i}\n")).collect();
    let meshes = vec!["\"k.obj\""; 20_000].join(", ");
    let times: Vec<String> = (0..20_000).map(|t| format!("{t}.0")).collect();
    let scene = format!("name = \"big\"\n[keyframes]\nmeshes = [{meshes}]\ntimes = [{}]\n", times.join(", "));
    let mut rows = Vec::new();
    let mut measure = |what: &str, text: &str, parse: &dyn Fn(&str) -> bool| {
        let (ok, peak) = alloc::peak(|| parse(text));
        assert!(ok, "{what} parses");
        let ratio = peak as f64 / text.len() as f64;
        assert!(ratio < ALLOC_PER_BYTE as f64, "{what}: {ratio:.1} bytes per input byte");
        rows.push(format!("{what}: {} bytes, peak {peak} bytes ({ratio:.1} per input byte)", text.len()));
    };
    measure("OBJ", &obj_text, &|t| obj::parse(t).is_ok());
    measure("MEDIT", &medit_text, &|t| medit::parse(t).is_ok());
    measure(".node", &node, &|t| tetgen_io::parse_node(t).is_ok());
    measure(".ele", &ele, &|t| tetgen_io::parse_ele(t, 0, v).is_ok());
    measure(".dmat", &dmat, &|t| selection::parse_dmat(t, v).is_ok());
    measure(".txt", &indices, &|t| selection::parse_indices(t, v).is_ok());
    measure("scene", &scene, &|t| Scene::parse(t).is_ok());
    eprintln!("{}", rows.join("\n"));
}

/// The seeds are valid, so the mutations start from files that parse.
#[test]
fn seeds_parse() {
    obj::parse(OBJ).unwrap();
    medit::parse(MEDIT).unwrap();
    let (points, first) = tetgen_io::parse_node(NODE).unwrap();
    tetgen_io::parse_ele(ELE, first, points.len()).unwrap();
    selection::parse_dmat(DMAT, 6).unwrap();
    selection::parse_indices(INDICES, 6).unwrap();
    Scene::parse(SCENE).unwrap();
    // The meter sees a parse's allocations.
    let (_, peak) = alloc::peak(|| vec![0u8; 4096]);
    assert!(peak >= 4096);
}
