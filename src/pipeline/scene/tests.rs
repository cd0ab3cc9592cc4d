use super::*;

const MINIMAL: &str = r#"
name = "twist"
[keyframes]
meshes = ["k0.obj", "k1.obj"]
times = [0.0, 0.5]
"#;

#[test]
fn minimal_scene_gets_defaults() {
    let s = Scene::parse(MINIMAL).unwrap();
    assert_eq!(s.fps, 60.0);
    assert_eq!(s.solver.method, Method::Spacetime);
    assert_eq!(s.export.formats, vec![Format::Usda, Format::Glb]);
    assert!(s.export.full_frame);
    assert_eq!((s.export.weights, s.export.gltf_interpolation), (Weights::Bernstein, GltfInterpolation::Linear));
    assert_eq!(s.export.gltf_compression, crate::formats::export::glb::Compression::Quantize);
    assert_eq!(s.keyframes.as_ref().unwrap().rest, Rest::Key(0));
}

#[test]
fn the_export_basis_follows_the_input_unless_given() {
    let e = Scene::parse(MINIMAL).unwrap().export;
    assert_eq!((e.basis, e.rank, e.basis_for(false), e.basis_for(true)), (None, None, Basis::Keys, Basis::Principal));
    let e = Scene::parse(&(MINIMAL.to_string() + "[export]\nbasis = \"keys\"\n")).unwrap().export;
    assert_eq!(e.basis_for(true), Basis::Keys);
    let e = Scene::parse(&(MINIMAL.to_string() + "[export]\nrank = 3\n")).unwrap().export;
    assert_eq!((e.basis_for(false), e.rank), (Basis::Principal, Some(3)), "a rank asks for the principal basis");
    for (extra, says) in [
        ("rank = 0\n", "[export] rank = 0"),
        ("basis = \"keys\"\nrank = 2\n", "basis = \"keys\" has no rank"),
        ("basis = \"pca\"\n", "unknown variant `pca`"),
        ("rank = -1\n", "invalid value"),
    ] {
        let e = Scene::parse(&(MINIMAL.to_string() + "[export]\n" + extra)).unwrap_err().to_string();
        assert!(e.contains(says) && e.contains("(fix: "), "{extra}: {e}");
    }
}

#[test]
fn a_partial_table_takes_the_other_defaults() {
    let s = Scene::parse(&(MINIMAL.to_string() + "[material]\nstiffness = 5.0\n[solver]\nsamples = 3\n[tet]\n")).unwrap();
    assert_eq!(s.material, Material { stiffness: 5.0, ..Material::default() });
    assert_eq!(s.solver, Solver { samples: 3, ..Solver::default() });
    assert_eq!((&s.tet, &s.export), (&Tet::default(), &Export::default()));
    assert_eq!(s.material.volume, 70.0, "the volume weight does not follow the strain weight");
    let s = Scene::parse(&(MINIMAL.to_string() + "[solver]\nsamples = 10\ncoarse_samples = 5\n")).unwrap();
    assert_eq!(s.solver, Solver { samples: 10, coarse_samples: 5, ..Solver::default() });
    assert_eq!(crate::pipeline::stages::solve::settings(&s).coarse_phase(), Some(5), "the key reaches the solver");
    let s = Scene::parse(&(MINIMAL.to_string() + "[solver]\nstep = \"gauss-newton\"\n")).unwrap();
    assert_eq!(
        crate::pipeline::stages::solve::settings(&s).step,
        crate::algorithms::spacetime::settings::Step::GaussNewton,
        "the key reaches the solver"
    );
    let e = Scene::parse(&(MINIMAL.to_string() + "[solver]\nstep = \"newton\"\n")).unwrap_err().to_string();
    assert!(e.contains("[solver] step = \"newton\" is not a step") && e.contains("(fix: "), "{e}");
}

#[test]
fn the_issue_example_parses() {
    let text = r#"
name = "twist"
fps = 60
[keyframes]
meshes = ["k0.obj", "k1.obj"]
times = [0.0, 0.5]
fixed = ["all", "top.txt"]
cyclic = false
[tet]
quality = 1.414
max_volume = 0.0
[material]
stiffness = 70.0
volume = 70.0
density = 1.0
damping = 0.1
gravity = [0.0, 0.0, 0.0]
[solver]
method = "hermite"
samples = 10
[export]
formats = ["usda", "glb"]
full_frame = true
"#;
    let s = Scene::parse(text).unwrap();
    assert_eq!(s.solver.method, Method::Hermite);
    let e = Scene::parse(
        &(MINIMAL.to_string() + "[export]\nweights = \"signed\"\ngltf_interpolation = \"cubicspline\"\ngltf_compression = \"meshopt\"\n"),
    )
    .unwrap()
    .export;
    assert_eq!((e.weights, e.gltf_interpolation), (Weights::Signed, GltfInterpolation::Cubicspline));
    assert_eq!(e.gltf_compression, crate::formats::export::glb::Compression::Meshopt);
    assert_eq!(s.keyframes.as_ref().unwrap().fixed, Some(vec![Selection::All, Selection::File { file: "top.txt".into(), invert: false }]));
}

#[test]
fn unknown_key_is_named_with_its_line() {
    let text = MINIMAL.to_string() + "[material]\nstifness = 3.0\n";
    let e = Scene::parse(&text).unwrap_err().to_string();
    assert!(e.contains("unknown field `stifness`"), "{e}");
    assert!(e.contains("line 7"), "{e}");
    assert!(e.contains("fix: remove or rename the key"), "{e}");
}

#[test]
fn selections_and_deformed_meshes_parse() {
    let text = r#"
name = "t"
[keyframes]
meshes = ["a.mesh", { mesh = "a.mesh", twist = { axis = "y", degrees = 180.0, axial_scale = 0.8 } }, { mesh = "a.mesh", offset = [0.0, 1.5, -2.0] }]
times = [0.0, 0.5, 1.0]
fixed = ["all", [{ axis = "y", max = 0.01 }, { axis = "y", min = 2.99 }], { file = "tail.dmat", invert = true }]
rest = "rest.mesh"
"#;
    let s = Scene::parse(text).unwrap();
    assert_eq!(s.keyframes.as_ref().unwrap().meshes[1].twist().unwrap().degrees, 180.0);
    assert_eq!(s.keyframes.as_ref().unwrap().meshes[1].offset(), None);
    assert_eq!(s.keyframes.as_ref().unwrap().meshes[2].offset(), Some([0.0, 1.5, -2.0]));
    assert_eq!(s.keyframes.as_ref().unwrap().meshes[2].twist(), None);
    for bad in ["[0.0, 1.0]", "[0.0, nan, 1.0]"] {
        let e = Scene::parse(&text.replace("[0.0, 1.5, -2.0]", bad)).unwrap_err().to_string();
        assert!(e.contains("expected 3 components") || e.contains("offset must be three finite numbers"), "{e}");
    }
    // A twist the solver could not use, or a stage file could not carry (found by the fuzzer).
    for (bad, says) in
        [("degrees = inf", "twist of inf degrees"), ("degrees = nan", "twist of NaN degrees"), ("axial_scale = 0.0", "axial_scale = 0")]
    {
        let twist = if bad.starts_with("degrees") { format!("{bad}, axial_scale = 0.8") } else { format!("degrees = 180.0, {bad}") };
        let e = Scene::parse(&text.replace("degrees = 180.0, axial_scale = 0.8", &twist)).unwrap_err().to_string();
        assert!(e.contains("meshes[1]") && e.contains(says) && e.contains("fix:"), "{e}");
    }
    assert_eq!(s.keyframes.as_ref().unwrap().rest, Rest::Mesh("rest.mesh".into()));
    let fixed = s.keyframes.unwrap().fixed.unwrap();
    assert_eq!(
        fixed[1],
        Selection::Union(vec![
            Selection::Slab { axis: Axis::Y, min: None, max: Some(0.01), invert: false },
            Selection::Slab { axis: Axis::Y, min: Some(2.99), max: None, invert: false },
        ])
    );
    assert_eq!(fixed[2], Selection::File { file: "tail.dmat".into(), invert: true });
}

#[test]
fn contacts_timing_and_obstacles_parse() {
    let text = r#"
name = "ball"
[keyframes]
meshes = ["a.obj", "b.obj", "c.obj"]
times = [0.0, 0.3, 0.6]
contact = [1]
[solver]
optimize_timing = true
keep_duration = true
fixed_times = [0]
contact_samples = 30
[[obstacle]]
kind = "plane"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
[[obstacle]]
kind = "sphere"
center = [0.0, -5.0, 0.0]
radius = 4.0
"#;
    let s = Scene::parse(text).unwrap();
    assert_eq!(s.keyframes.as_ref().unwrap().contact, vec![1]);
    assert!(s.solver.optimize_timing && s.solver.keep_duration && s.solver.contact_samples == 30);
    assert_eq!(s.obstacles.len(), 2);
    assert_eq!(s.obstacles[1], ObstacleSpec::Sphere { center: [0.0, -5.0, 0.0], radius: 4.0 });
    let back: Scene = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
    assert_eq!(back, s);
    let cases = [
        (text.replace("contact = [1]", "contact = [2]"), "needs a key before and after"),
        (text.replace("radius = 4.0", "radius = 0.0"), "radius is not positive"),
        (text.replace("normal = [0.0, 1.0, 0.0]", "normal = [0.0, 0.0, 0.0]"), "normal is zero"),
        (text.replace("kind = \"plane\"", "kind = \"cone\""), "unknown variant `cone`"),
        (text.replace("radius = 4.0", "radius = 4.0\nheight = 2.0"), "unknown field `height`"),
        (text.replace("fixed_times = [0]", "fixed_times = [3]"), "fixed_times lists key 3"),
        (text.replace("optimize_timing = true", "optimize_timing = false"), "keep_duration is set but optimize_timing is false"),
        (text.replace("times = [0.0, 0.3, 0.6]", "times = [0.0, 0.3, 0.3]"), "contact = [k]"),
    ];
    for (text, expect) in cases {
        let e = Scene::parse(&text).unwrap_err().to_string();
        assert!(e.contains(expect), "expected {expect:?} in {e}");
        assert!(e.contains("(fix: "), "{e}");
    }
}

#[test]
fn selections_round_trip_through_json() {
    let text = r#"
name = "t"
[keyframes]
meshes = ["a.mesh", "a.mesh", "a.mesh", "a.mesh", "a.mesh"]
times = [0.0, 0.5, 1.0, 1.5, 2.0]
fixed = ["all", "none", "ends.txt", { file = "tail.dmat", invert = true }, [{ axis = "y", max = 0.01 }, { axis = "x", min = -1.0, max = 1.0, invert = true }]]
"#;
    let s = Scene::parse(text).unwrap();
    let json = serde_json::to_string(&s).unwrap();
    let back: Scene = serde_json::from_str(&json).unwrap();
    assert_eq!(back, s, "{json}");
}

#[test]
fn unknown_key_inside_a_selection_table_is_named() {
    let text = MINIMAL.replace("times", "fixed = [\"all\", { axis = \"y\", maximum = 1.0 }]\ntimes");
    let e = Scene::parse(&text).unwrap_err().to_string();
    assert!(e.contains("unknown field `maximum`"), "{e}");
}

#[test]
fn nonsense_values_are_rejected() {
    let sel = |entry: &str| MINIMAL.replace("times", &format!("fixed = [\"all\", {entry}]\ntimes"));
    let cases = [
        (MINIMAL.to_string() + "[material]\ngravity = [0.0, -9.8, 0.0, 1.0]\n", "expected 3 components (x, y, z), found 4"),
        (MINIMAL.to_string() + "[material]\ngravity = [0.0, -9.8]\n", "found 2"),
        (sel("{ axis = \"y\", min = nan }"), "[keyframes] fixed[1]: the y slab has min = nan"),
        (sel("[\"none\", { axis = \"x\", max = nan }]"), "the x slab has max = nan"),
        (sel("{ axis = \"z\", min = 2.0, max = 1.0 }"), "the z slab has min = 2 > max = 1, so it selects nothing"),
        (MINIMAL.replace("name = \"twist\"", "name = \"a\\nb\""), "name `a\\nb` cannot be a file stem: it contains a control character"),
        (MINIMAL.replace("name = \"twist\"", "name = \"\\u001b[31mred\""), "contains a control character"),
        (MINIMAL.replace("name = \"twist\"", "name = \"a\\\\b\""), "contains a path separator"),
        (MINIMAL.replace("name = \"twist\"", "name = \"../x\""), "contains a path separator"),
        (MINIMAL.replace("name = \"twist\"", "name = \".hidden\""), "starts with '.'"),
        (MINIMAL.replace("name = \"twist\"", "name = \"\""), "is empty"),
        (MINIMAL.replace("name = \"twist\"", &format!("name = \"{}\"", "n".repeat(300))), "is longer than 200 bytes"),
    ];
    for (text, expect) in cases {
        let e = Scene::parse(&text).unwrap_err().to_string();
        assert!(e.contains(expect), "expected {expect:?} in {e}");
        assert!(e.contains("(fix: ") && !e.contains('\n') && !e.contains('\u{1b}'), "{e}");
    }
    assert!(Scene::parse(&sel("{ axis = \"y\", min = 1.0, max = 1.0 }")).is_ok(), "a slab of zero thickness is fine");
}

#[test]
fn units_are_a_name_or_meters_and_the_old_key_is_their_alias() {
    let mpu = |extra: &str| Scene::parse(&MINIMAL.replacen("\n", &format!("\n{extra}\n"), 1)).map(|s| s.meters_per_unit());
    assert_eq!(mpu("").unwrap(), 1.0);
    assert_eq!(mpu("units = \"cm\"").unwrap(), 0.01);
    assert_eq!(mpu("units = 100").unwrap(), 100.0);
    assert_eq!(mpu("units = 0.0254").unwrap(), 0.0254);
    assert_eq!(Scene::parse(&(MINIMAL.to_string() + "[export]\nmeters_per_unit = 0.001\n")).unwrap().meters_per_unit(), 0.001);
    for (bad, says) in [("units = \"yd\"", "units = \"yd\" is not a length unit"), ("units = -1", "units = -1e0 is not a length unit")] {
        let e = mpu(bad).unwrap_err().to_string();
        assert!(e.contains(says) && e.contains("\"cm\""), "{e}");
    }
    let both = MINIMAL.replacen("\n", "\nunits = \"cm\"\n", 1) + "[export]\nmeters_per_unit = 0.001\n";
    assert!(Scene::parse(&both).unwrap_err().to_string().contains("disagree"));
}

#[test]
fn invalid_values_are_rejected_with_a_fix() {
    let cases = [
        (MINIMAL.replace("[0.0, 0.5]", "[0.5, 0.0]"), "times decrease"),
        (MINIMAL.replace("[0.0, 0.5]", "[0.0]"), "2 meshes but 1 times"),
        (MINIMAL.replace("name = \"twist\"", "name = \"a/b\""), "cannot be a file stem"),
        (MINIMAL.to_string() + "[solver]\nsamples = 0\n", "samples = 0"),
        (MINIMAL.to_string() + "[solver]\nmethod = \"magic\"\n", "unknown variant `magic`"),
        (MINIMAL.to_string() + "[export]\nformats = [\"fbx\"]\n", "unknown variant `fbx`"),
        (MINIMAL.to_string() + "[export]\nweights = \"positive\"\n", "unknown variant `positive`"),
        (MINIMAL.to_string() + "[export]\ngltf_interpolation = \"step\"\n", "unknown variant `step`"),
        (MINIMAL.to_string() + "[export]\ngltf_compression = \"draco\"\n", "unknown variant `draco`"),
    ];
    for (text, expect) in cases {
        let e = Scene::parse(&text).unwrap_err().to_string();
        assert!(e.contains(expect), "expected {expect:?} in {e}");
        assert!(e.contains("(fix: "), "{e}");
    }
}
