//! Textures through the CLI: the octagonal prism of `attributes` (a UV seam where u wraps from
//! 1 to 0, two material groups) with a `.mtl` whose `map_Kd` names a PNG written here, baked
//! to usda/usdc/glb.
//!
//! - glb: every primitive's material has a `baseColorTexture` showing the embedded PNG, byte
//!   for byte; the glTF validator (0 errors, 0 warnings) and three.js morphing pass
//!   (`check_outputs`).
//! - Chromium: three.js renders the glb with its own texture at the three key times and the
//!   matching OBJ keyframe through three's OBJLoader with the PNG (an independent path: the
//!   OBJ's own `vt`), unlit, from the same camera: the pixels agree. Two copies of the glb with
//!   the UVs broken the ways a writer could break them (v not flipped to glTF's convention;
//!   the seam copies' UVs exchanged with their points') must fail the same comparison, so it
//!   is not vacuous.
//! - USD: each group's material is a UsdPreviewSurface whose diffuseColor comes from a
//!   UsdUVTexture reading the PNG (copied beside the file, a relative asset path) at the
//!   `st` primvar, as usd-core resolves it.

use std::path::Path;

use crate::attributes::{prism_obj, Glb, SCENE};
use crate::common::checkers::{check_texture, usd_probe};
use crate::common::cli::{read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

/// A PNG (8-bit RGB, no interlace) with stored (uncompressed) deflate blocks: every decoder
/// reads it, and the test needs no image crate.
pub(crate) fn png(width: usize, height: usize, pixel: impl Fn(usize, usize) -> [u8; 3]) -> Vec<u8> {
    let mut raw = Vec::with_capacity(height * (1 + 3 * width));
    for y in 0..height {
        raw.push(0); // filter: none
        for x in 0..width {
            raw.extend(pixel(x, y));
        }
    }
    let mut zlib = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = raw.chunks(65535).collect();
    for (i, block) in blocks.iter().enumerate() {
        zlib.push((i + 1 == blocks.len()) as u8);
        let n = block.len() as u16;
        zlib.extend(n.to_le_bytes());
        zlib.extend((!n).to_le_bytes());
        zlib.extend_from_slice(block);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &x in &raw {
        a = (a + x as u32) % 65521;
        b = (b + a) % 65521;
    }
    zlib.extend(((b << 16) | a).to_be_bytes());
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        out.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        out.extend_from_slice(&body);
        out.extend(crc32(&body).to_be_bytes());
    };
    let mut header = Vec::new();
    header.extend((width as u32).to_be_bytes());
    header.extend((height as u32).to_be_bytes());
    header.extend([8, 2, 0, 0, 0]);
    chunk(b"IHDR", &header);
    chunk(b"IDAT", &zlib);
    chunk(b"IEND", &[]);
    out
}

/// The CRC-32 of a PNG chunk (its type and data).
pub(crate) fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 { 0xedb8_8320 ^ (c >> 1) } else { c >> 1 };
        }
    }
    !c
}

/// A UV-colour texture: red grows with u, green with v (OBJ's v, up the image), blue an 8 x 8
/// checker; never black, so the renders tell the mesh from the background.
pub(crate) fn uv_texture() -> Vec<u8> {
    const N: usize = 64;
    png(N, N, |x, y| {
        let (u, v) = ((x as f64 + 0.5) / N as f64, 1.0 - (y as f64 + 0.5) / N as f64);
        [(40.0 + 200.0 * u) as u8, (40.0 + 200.0 * v) as u8, if (x / 8 + y / 8) % 2 == 0 { 230 } else { 40 }]
    })
}

/// The textured prism scene in `dir`: rest.obj, long.obj, prism.mtl, uvgrid.png, scene.toml
/// (with `extra` lines added to its `[export]` table).
pub(crate) fn textured_prism(dir: &Path, extra: &str) {
    for (name, stretch) in [("rest.obj", 1.0), ("long.obj", 1.3)] {
        std::fs::write(dir.join(name), format!("mtllib prism.mtl\n{}", prism_obj(stretch))).unwrap();
    }
    std::fs::write(dir.join("prism.mtl"), "newmtl side\nKd 1 1 1\nmap_Kd uvgrid.png\n\nnewmtl cap\nmap_Kd -s 1 1 1 uvgrid.png\n").unwrap();
    std::fs::write(dir.join("uvgrid.png"), uv_texture()).unwrap();
    std::fs::write(dir.join("scene.toml"), SCENE.replace("[export]\n", &format!("[export]\n{extra}\n"))).unwrap();
}

/// usd-core's view of each group material: the shader feeding diffuseColor, its file (resolved)
/// and the primvar its st reads.
const USD_PROBE: &str = r#"
import json, sys
from pxr import Usd, UsdGeom, UsdShade
stage = Usd.Stage.Open(sys.argv[1])
mesh = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)][0]
out = {}
for s in UsdGeom.Subset.GetAllGeomSubsets(mesh):
    material = UsdShade.MaterialBindingAPI(s.GetPrim()).ComputeBoundMaterial()[0]
    surface = material.ComputeSurfaceSource()[0]
    diffuse = surface.GetInput("diffuseColor")
    source = diffuse.GetConnectedSources()[0]
    texture = UsdShade.Shader(source[0].source.GetPrim()) if source else None
    entry = {"surface": surface.GetIdAttr().Get()}
    if texture:
        st = texture.GetInput("st").GetConnectedSources()[0][0].source
        reader = UsdShade.Shader(st.GetPrim())
        entry.update(texture=texture.GetIdAttr().Get(), output=source[0].sourceName, file=texture.GetInput("file").Get().resolvedPath,
                     reader=reader.GetIdAttr().Get(), varname=reader.GetInput("varname").Get())
    out[s.GetPrim().GetName()] = entry
print(json.dumps(out))
"#;

/// A change to a glb's UVs (u, v pairs), given the seam copies' points and the point count.
type UvChange = dyn Fn(&mut [f32], &[u64], usize);

#[test]
fn textured_obj_renders_with_its_texture_in_chromium_and_usd_references_it() {
    let dir = TempDir::new("texture");
    textured_prism(&dir.path, "");
    run(&dir.path, &["bake", "scene.toml", "--out", "out"]).success();
    let out = dir.join("out");
    let outputs = output_files(&read_json(&out.join("report.json"))["outputs"]);
    let anim = library_animation(&dir.join("scene.toml"));
    let a = anim.mesh.attributes.as_ref().unwrap();
    assert_eq!(a.textures.len(), 2, "map_Kd of both groups: {:?}", a.textures);
    check_outputs(&out, &anim, &outputs);
    let png = uv_texture();
    assert_eq!(std::fs::read(out.join("uvgrid.png")).unwrap(), png, "the texture is copied beside the USD files");
    assert!(outputs.iter().all(|f| !f.path.ends_with(".png")), "the texture is not one of the compared outputs");

    // glb: one embedded image, the PNG's bytes, the base colour of both groups.
    let glbs: Vec<String> = outputs.iter().filter(|f| f.path.ends_with(".glb")).map(|f| f.path.clone()).collect();
    assert_eq!(glbs.len(), 2);
    for name in &glbs {
        let glb = Glb::parse(&std::fs::read(out.join(name)).unwrap());
        let images = glb.json["images"].as_array().expect("images");
        assert_eq!(images.len(), 1, "{name}: one image for the two groups that share it");
        assert_eq!(images[0]["mimeType"], "image/png");
        let view = &glb.json["bufferViews"][images[0]["bufferView"].as_u64().unwrap() as usize];
        let start = view["byteOffset"].as_u64().unwrap_or(0) as usize;
        assert_eq!(&glb.bin[start..start + view["byteLength"].as_u64().unwrap() as usize], &png[..], "{name}");
        for p in glb.json["meshes"][0]["primitives"].as_array().unwrap() {
            let material = &glb.json["materials"][p["material"].as_u64().unwrap() as usize];
            let texture = material["pbrMetallicRoughness"]["baseColorTexture"]["index"].as_u64().expect("baseColorTexture");
            assert_eq!(glb.json["textures"][texture as usize]["source"], 0, "{name}");
        }
    }

    // USD: UsdPreviewSurface <- UsdUVTexture(file = the copy) <- UsdPrimvarReader_float2("st").
    for file in outputs.iter().filter(|f| f.path.contains(".usd")) {
        let v = usd_probe(USD_PROBE, &out.join(&file.path));
        for group in ["side", "cap"] {
            let g = &v[group];
            assert_eq!(
                (g["surface"].as_str(), g["texture"].as_str(), g["output"].as_str()),
                (Some("UsdPreviewSurface"), Some("UsdUVTexture"), Some("rgb")),
                "{}: {v}",
                file.path
            );
            assert_eq!((g["reader"].as_str(), g["varname"].as_str()), (Some("UsdPrimvarReader_float2"), Some("st")), "{}: {v}", file.path);
            let resolved = g["file"].as_str().unwrap();
            assert!(!resolved.is_empty() && std::fs::read(resolved).unwrap() == png, "{}: the texture resolves to the copy: {v}", file.path);
        }
    }

    // Chromium: the glb (and the full-frame glb) against the OBJ keys; two broken copies.
    let blendshape = out.join("uvprism.glb");
    let broken = |what: &str, change: &UvChange| {
        let mut bytes = std::fs::read(&blendshape).unwrap();
        let glb = Glb::parse(&bytes);
        let mesh = &glb.json["meshes"][0];
        let a = mesh["primitives"][0]["attributes"]["TEXCOORD_0"].as_u64().unwrap();
        let mut uvs = glb.floats(a, 2);
        let sources: Vec<u64> = mesh["extras"]["seamSources"].as_array().unwrap().iter().map(|x| x.as_u64().unwrap()).collect();
        let points = uvs.len() / 2 - sources.len();
        change(&mut uvs, &sources, points);
        let (start, stride, _) = glb.start(a);
        let bin = bytes.len() - glb.bin.len();
        for (i, uv) in uvs.chunks(2).enumerate() {
            for (k, x) in uv.iter().enumerate() {
                let at = bin + start + i * stride.max(8) + 4 * k;
                bytes[at..at + 4].copy_from_slice(&x.to_le_bytes());
            }
        }
        let path = dir.join(format!("broken-{what}.glb"));
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let flipped = broken("v-not-flipped", &|uvs, _, _| uvs.iter_mut().skip(1).step_by(2).for_each(|v| *v = 1.0 - *v));
    let shuffled = broken("seam-copies-shuffled", &|uvs, sources, points| {
        for (j, &s) in sources.iter().enumerate() {
            let (c, p) = (2 * (points + j), 2 * s as usize);
            uvs.swap(c, p);
            uvs.swap(c + 1, p + 1);
        }
    });
    let files = [blendshape.as_path(), &out.join("uvprism.full.glb"), &flipped, &shuffled];
    let (rest, long) = (dir.join("rest.obj"), dir.join("long.obj"));
    let poses = [(0.0, rest.as_path()), (0.5, long.as_path()), (1.0, rest.as_path())];
    // Looking at the seam (u = 1 meets u = 0 at +x) from the side and above.
    let summary = check_texture(&files, &dir.join("uvgrid.png"), &dir.join("renders"), &poses, [1.0, 0.6, -0.5]);
    assert!(summary["issues"].as_array().unwrap().is_empty(), "{summary}");
    let results = summary["files"].as_array().unwrap();
    for f in results {
        let mismatch: Vec<f64> = f["results"].as_array().unwrap().iter().map(|r| r["mismatch"].as_f64().unwrap()).collect();
        eprintln!("texture render {}: mismatch per key {mismatch:?}, ok {}", f["file"], f["ok"]);
    }
    for f in &results[..2] {
        assert_eq!(f["ok"], true, "the glb renders its texture where the OBJ has it: {f}");
    }
    for f in &results[2..] {
        assert_eq!(f["ok"], false, "a broken UV layout must fail the comparison: {f}");
        let worst = f["results"].as_array().unwrap().iter().map(|r| r["mismatch"].as_f64().unwrap()).fold(0.0, f64::max);
        assert!(worst > 0.05, "{f}");
    }
}

/// Bad textures are one-line errors naming the file, with exit code 1 and no output folder: a
/// `map_Kd` naming a missing file or an image that is neither PNG nor JPEG (the `.mtl` and its
/// line, found before the solve).
#[test]
fn missing_or_unsupported_textures_are_one_line_errors() {
    let dir = TempDir::new("texture-errors");
    textured_prism(&dir.path, "formats = [\"glb\"]\nfull_frame = false");
    std::fs::write(
        dir.join("scene.toml"),
        std::fs::read_to_string(dir.join("scene.toml")).unwrap().replace("formats = [\"usda\", \"usdc\", \"glb\"]\n", ""),
    )
    .unwrap();
    std::fs::write(dir.join("prism.mtl"), "newmtl side\nmap_Kd gone.png\n").unwrap();
    let r = run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert_eq!(r.stderr.trim().lines().count(), 1, "{r}");
    assert!(r.stderr.contains("prism.mtl: line 2: map_Kd names the texture `gone.png`") && r.stderr.contains("(fix: "), "{r}");
    std::fs::write(dir.join("prism.mtl"), "newmtl side\nmap_Kd uvgrid.gif\n").unwrap();
    std::fs::write(dir.join("uvgrid.gif"), b"GIF89a....").unwrap();
    let r = run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert!(r.stderr.contains("prism.mtl: line 2: map_Kd names the texture `uvgrid.gif`, which is not a PNG or JPEG image"), "{r}");
    assert!(!dir.join("out").exists(), "no partial output");
}

#[test]
fn a_staged_folder_with_textures_can_be_moved_and_resumed() {
    // Stage files name textures relative to their own folder: a folder staged by `import` and
    // `tetrahedralize`, moved elsewhere, resumes (`solve`, `embed`, `export`) to the bake's bytes.
    let dir = TempDir::new("texture-moved");
    let staged = dir.join("staged");
    std::fs::create_dir_all(staged.join("stages")).unwrap();
    textured_prism(&staged, "");
    run(&staged, &["import", "scene.toml", "-o", "keys.json"]).success();
    run(&staged, &["tetrahedralize", "keys.json", "-o", "stages/body.json"]).success();
    let canonical = staged.canonicalize().unwrap();
    for (file, texture) in [("keys.json", "\"uvgrid.png\""), ("stages/body.json", "\"../uvgrid.png\"")] {
        let text = std::fs::read_to_string(staged.join(file)).unwrap();
        assert!(text.contains(texture) && !text.contains(canonical.to_str().unwrap()), "{file}: the texture relative to it, no absolute path");
    }
    let moved = dir.join("moved");
    std::fs::rename(&staged, &moved).unwrap();
    run(&moved, &["solve", "stages/body.json", "-o", "stages/solution.json"]).success();
    run(&moved, &["embed", "stages/solution.json", "-o", "animation.json"]).success();
    run(&moved, &["export", "animation.json", "--out", "out"]).success();
    run(&moved, &["bake", "scene.toml", "--out", "baked"]).success();
    for file in ["uvprism.glb", "uvprism.usda", "uvgrid.png"] {
        assert_eq!(std::fs::read(moved.join("out").join(file)).unwrap(), std::fs::read(moved.join("baked").join(file)).unwrap(), "{file}");
    }
}
