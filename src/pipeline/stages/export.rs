//! The `export` stage: the animation's blendshape and full-frame files.
//!
//! Contract: build the [`BlendShapeClip`] (blendshapes, in the form `[export] weights`
//! names) and the `FullFrame` (one pose per frame: the animation sampled at every frame, or
//! for a cache bake the cache itself, frame for frame), and stage, for each
//! format in `scene.export.formats`, `NAME.EXT` (blendshapes) and, when `full_frame`,
//! `NAME.full.EXT` (full-frame). `usda` and `usdc` hold the same USD layer (`export::usd`).
//! Returns the list of staged files with their sizes. The files (and whatever the caller
//! stages after them, e.g. `NAME.outputs.json`) are in the staging group `export:NAME`: a
//! commit removes the files an earlier export of the same scene wrote that this one did not,
//! (the USD files' textures, copied beside them, are in the group but not in `Outputs`),
//! and keeps the report and other scenes' files. The layouts are specified in
//! `formats/usd.md` and `formats/gltf.md`.

use super::import_cache::{error_against, reopen};
use crate::algorithms::blendshape::clip::BlendShapeClip;
use crate::algorithms::blendshape::fullframe::FullFrame;
use crate::algorithms::blendshape::principal::{smallest_rank, Components};
use crate::algorithms::geometry::{bbox_diagonal, Axis};
use crate::formats::export::{glb, texture, usd, usda, usdc, weld_map};
use crate::pipeline::report::measures::deviation;
use crate::pipeline::scene::{Basis, Format, GltfInterpolation, Method, Scene, DEFAULT_TOLERANCE};
use crate::pipeline::stage_file::{Animation, OutputFile, OutputKind, Outputs};
use crate::support::budget::Budget;
use crate::support::error::{quoted, Error, Result};
use crate::support::output::Staging;
use crate::support::progress::Progress;
use rayon::prelude::*;

/// Stage every requested file (written in parallel); `Outputs` lists them blendshapes first,
/// then full-frame, each in the order usda, usdc, glb, whatever order the scene file gives.
pub fn export(animation: &Animation, budget: &Budget, staging: &mut Staging) -> Result<Outputs> {
    let clip = blendshape_clip(animation, None, budget)?;
    export_with(animation, &clip, staging, budget, &Progress::hidden())
}

/// [`export`] of `clip` (the animation's [`blendshape_clip`], chosen once by the caller, who
/// may also measure it), showing a bar over the files on `progress`.
pub fn export_with(
    animation: &Animation,
    clip: &(BlendShapeClip, Option<usize>),
    staging: &mut Staging,
    budget: &Budget,
    progress: &Progress,
) -> Result<Outputs> {
    check(animation)?;
    let scene = &animation.scene;
    staging.set_group(&format!("export:{}", scene.name));
    let trajectory = &animation.trajectory;
    let triangles = &animation.mesh.triangles;
    let attributes = animation.mesh.attributes.as_ref();
    let mut formats = scene.export.formats.clone();
    formats.sort();
    formats.dedup();
    let settings = usd::UsdSettings {
        name: usd::prim_name(&scene.name),
        fps: scene.fps,
        up_axis: if scene.export.up_axis == Axis::Z { 'Z' } else { 'Y' },
        meters_per_unit: scene.meters_per_unit(),
    };
    let placement = glb::Placement { z_up: scene.export.up_axis == Axis::Z, meters_per_unit: scene.meters_per_unit() };
    let diagonal = bbox_diagonal(&animation.mesh.positions);
    let tolerance = animation.cache.as_ref().and_then(|c| c.tolerance).unwrap_or(DEFAULT_TOLERANCE);
    let encoding = glb::Encoding { compression: scene.export.gltf_compression, max_error: QUANTIZATION_SHARE * tolerance * diagonal };
    let frame_times: Vec<f64> = trajectory.frames(scene.fps).iter().map(|f| f.1).collect();

    let (clip, rank) = (&clip.0, clip.1);
    // A cache bake's full-frame files are the cache itself, frame for frame: what the
    // blendshape files replace.
    let full = match (&animation.cache, scene.export.full_frame) {
        (_, false) => None,
        (Some(record), true) => Some(
            FullFrame::from_source(reopen(record, budget)?.frames.as_mut(), scene.fps)
                .map_err(|e| e.with_path(std::path::Path::new(&record.path)))?,
        ),
        (None, true) => Some(FullFrame::from_trajectory(trajectory, scene.fps)),
    };
    // The groups' diffuse textures (OBJ map_Kd): embedded in glb, copied beside USD files.
    let textures = texture::load(attributes.map_or(&[][..], |a| &a.textures), budget)?;
    // A welded input (keyframe surface or cache): every file says which of its vertices each
    // input vertex is.
    let weld = animation.weld_map();
    let surface = glb::Surface { triangles, attributes, textures: &textures, morph_normals: false, weld_map: weld };
    let blendshape_surface = glb::Surface { morph_normals: scene.export.gltf_morph_normals, ..surface };
    if formats.iter().any(|f| matches!(f, Format::Usda | Format::Usdc)) {
        // Beside the USD files a texture named like a file the run writes would be overwritten.
        let taken: Vec<String> =
            file_names(scene).into_iter().chain(crate::pipeline::report::FILES.map(String::from)).chain([outputs_list_name(scene)]).collect();
        let sources = attributes.map_or(&[][..], |a| &a.textures);
        for (source, t) in sources.iter().zip(&textures) {
            if let (Some(source), Some(t)) = (source, t) {
                if taken.contains(&t.file_name) {
                    return Err(Error::in_file(
                        source,
                        format!(
                            "the texture's file name {} is that of a file the bake writes beside the USD files, so one would overwrite the other",
                            quoted(&t.file_name)
                        ),
                        "rename the texture and its .mtl map_Kd line",
                    ));
                }
            }
        }
        let mut copied: Vec<&str> = Vec::new();
        for t in textures.iter().flatten() {
            if !copied.contains(&t.file_name.as_str()) {
                staging.write(&t.file_name, &t.bytes)?;
                copied.push(&t.file_name);
            }
        }
    }
    let forms = forms(scene);
    let bar = progress.bar((forms.len() * formats.len()) as u64, "export");
    // Only the blendshape form builds its layer: the full-frame USD files are written from
    // `full` itself, its points streamed (`usda::write_full_frame`, `usdc::write_full_frame`),
    // never copied into a layer or held as text or bytes.
    let layer = formats.iter().any(|f| matches!(f, Format::Usda | Format::Usdc)).then(|| {
        let mut layer = usd::blendshapes(clip, triangles, attributes, &settings);
        if let Some(map) = weld {
            weld_map::usd(&mut layer, map);
        }
        layer
    });
    let layer = layer.as_ref();
    // Every file at once: each writer makes its own file from shared inputs, so the files are
    // the bytes the writers make one after another (the order of `Outputs` is the jobs'). One
    // job per file, so a thread that finishes the small blendshape files takes a full-frame one.
    let jobs: Vec<(OutputKind, Format)> = forms.iter().flat_map(|&kind| formats.iter().map(move |&format| (kind, format))).collect();
    let shared: &Staging = staging;
    let written: Vec<Result<Option<f64>>> = jobs
        .par_iter()
        .with_max_len(1)
        .map(|&(kind, format)| {
            let name = file_name(&scene.name, kind, format);
            let streamed = kind == OutputKind::FullFrame;
            let io = |e: std::io::Error| Error::io(shared.final_path(&name), &e, "write an output file");
            let put = |bytes: &[u8]| -> Result<()> {
                let mut file = shared.create(&name)?;
                std::io::Write::write_all(&mut file, bytes).map_err(io)
            };
            let mut quantization_error = None;
            match format {
                Format::Usda => match &full {
                    Some(full) if streamed => {
                        let mut w = std::io::BufWriter::new(shared.create(&name)?);
                        usda::write_full_frame(full, triangles, attributes, &settings, weld, &mut w)
                            .and_then(|_| std::io::Write::flush(&mut w))
                            .map_err(io)?;
                    }
                    _ => put(usda::text(layer.expect("built for USD")).as_bytes())?,
                },
                Format::Usdc => {
                    // The interruption tests stop here: in the export, before the usdc is staged.
                    crate::support::interrupt::pause_point("usdc", "");
                    match &full {
                        Some(full) if streamed => {
                            usdc::write_full_frame(full, triangles, attributes, &settings, weld, &shared.final_path(&name), shared.create(&name)?)?
                        }
                        _ => put(&usdc::bytes(layer.expect("built for USD"), &shared.final_path(&name))?)?,
                    }
                }
                Format::Glb => {
                    let file = match (&kind, &full) {
                        (OutputKind::FullFrame, Some(full)) => glb::full_frame(full, surface, &scene.name, placement, encoding),
                        _ if scene.export.gltf_interpolation == GltfInterpolation::Linear => {
                            glb::blendshapes_sampled(clip, &frame_times, blendshape_surface, &scene.name, placement, encoding)
                        }
                        _ => glb::blendshapes(clip, blendshape_surface, &scene.name, placement, encoding),
                    };
                    let mut w = std::io::BufWriter::new(shared.create(&name)?);
                    file.write_to(&mut w).and_then(|_| std::io::Write::flush(&mut w)).map_err(io)?;
                    drop((w, file));
                    // What the file plays at every frame against what it was given, read back:
                    // a full-frame file holds `full` (a cache bake's is the cache, not the
                    // trajectory), at its own times.
                    let written = shared.path(&name);
                    quantization_error = match (&kind, &full) {
                        (OutputKind::FullFrame, Some(full)) => {
                            let held = |t: f64| {
                                let frame = full.times.partition_point(|&x| x < t).min(full.times.len() - 1);
                                full.points[frame].iter().map(|p| p.map(f64::from)).collect()
                            };
                            glb::readback::played_error_of_file(&written, (&full.times, scene.fps), &held, placement, diagonal)?
                        }
                        _ => glb::readback::played_error_of_file(&written, (&frame_times, scene.fps), &|t| clip.points_at(t), placement, diagonal)?,
                    };
                }
            }
            bar.inc(1);
            Ok(quantization_error)
        })
        .collect();
    let mut files = Vec::new();
    for ((kind, format), quantization_error) in jobs.into_iter().zip(written) {
        let quantization_error = quantization_error?;
        let name = file_name(&scene.name, kind, format);
        staging.record(&name);
        files.push(OutputFile { bytes: staging.size(&name)?, path: name, kind, format, quantization_error });
    }
    bar.finish_and_clear();
    Ok(Outputs { files, rank })
}

/// The forms the scene exports: blendshapes, and full-frame when `[export] full_frame`.
fn forms(scene: &Scene) -> Vec<OutputKind> {
    let mut forms = vec![OutputKind::Blendshape];
    if scene.export.full_frame {
        forms.push(OutputKind::FullFrame);
    }
    forms
}

/// `NAME.EXT` (blendshapes) or `NAME.full.EXT` (full-frame).
fn file_name(name: &str, kind: OutputKind, format: Format) -> String {
    let suffix = if kind == OutputKind::FullFrame { ".full" } else { "" };
    format!("{name}{suffix}.{}", format.extension())
}

/// The names of the files [`export_with`] stages for `scene`, its textures aside (they are
/// known once the meshes are read).
pub fn file_names(scene: &Scene) -> Vec<String> {
    forms(scene).into_iter().flat_map(|kind| scene.export.formats.iter().map(move |&f| file_name(&scene.name, kind, f))).collect()
}

/// `NAME.outputs.json`: the list of files `blendsim export` writes beside them.
pub fn outputs_list_name(scene: &Scene) -> String {
    format!("{}.outputs.json", scene.name)
}

/// The share of the scene's tolerance (`[cache] tolerance`, or its default) a glb's quantization
/// may add, of the bounding-box diagonal (`formats/gltf.md`, "Quantization").
pub(crate) const QUANTIZATION_SHARE: f64 = 0.1;

/// Reduction error allowed when a principal clip has no tolerance to meet (a keyframe scene):
/// the trajectory to f32 precision, of the bounding-box diagonal.
pub const PRINCIPAL_EXACT: f64 = 1e-6;

/// The blendshape clip of `animation` in the scene's `[export] basis` and `weights`, and for a
/// principal basis its rank: `rank` when given (the report rebuilding the exported clip), else
/// `[export] rank`, else the smallest rank that meets
/// - for a cache: the tolerance (`[cache] tolerance`, its default for listed keys) against
///   every cache frame, or, when the unreduced animation is itself farther from the cache than
///   that (spacetime), the tolerance against the unreduced animation at every frame;
/// - for keyframes: [`PRINCIPAL_EXACT`] against the animation at every frame.
pub fn blendshape_clip(animation: &Animation, rank: Option<usize>, budget: &Budget) -> Result<(BlendShapeClip, Option<usize>)> {
    let export = &animation.scene.export;
    let tr = &animation.trajectory;
    if export.basis_for(animation.cache.is_some() && animation.log.method == Method::Fit) == Basis::Keys {
        return Ok((BlendShapeClip::new(tr, export.weights), None));
    }
    let frames = tr.frames(animation.scene.fps);
    let components = Components::new(tr, &frames.iter().map(|&(_, t)| t).collect::<Vec<_>>());
    let rank = match rank.or(export.rank) {
        Some(r) => r.min(components.len().max(1)),
        None => {
            let diagonal = bbox_diagonal(&animation.mesh.positions);
            let from_animation = |clip: &BlendShapeClip| deviation(frames.iter().map(|&(_, t)| (clip.points_at(t), tr.evaluate(t))), diagonal).max;
            match &animation.cache {
                Some(record) => {
                    let tolerance = record.tolerance.unwrap_or(DEFAULT_TOLERANCE);
                    if error_against(record, tr, budget)?.max <= tolerance {
                        smallest_rank(&components, export.weights, |clip| {
                            Ok(error_against(record, &clip.played(&tr.times), budget)?.max <= tolerance)
                        })?
                    } else {
                        smallest_rank::<Error>(&components, export.weights, |clip| Ok(from_animation(clip) <= tolerance))?
                    }
                }
                None => smallest_rank::<Error>(&components, export.weights, |clip| Ok(from_animation(clip) <= PRINCIPAL_EXACT))?,
            }
        }
    };
    Ok((components.clip(rank, export.weights), Some(rank)))
}

/// The invariants the writers rely on; an animation file that breaks them was not written by
/// `blendsim embed` (or was edited).
fn check(animation: &Animation) -> Result<()> {
    const FIX: &str = "re-run `blendsim embed` to rewrite the animation file";
    let bad = |problem: String| Err(Error::general(format!("cannot export: the animation {problem}"), FIX));
    let tr = &animation.trajectory;
    let n = animation.mesh.positions.len();
    if tr.key_count() < 2 || tr.positions.len() != tr.key_count() || tr.velocities.len() != tr.key_count() {
        return bad(format!(
            "has {} key times, {} key poses and {} key velocities (need the same number, at least 2)",
            tr.key_count(),
            tr.positions.len(),
            tr.velocities.len()
        ));
    }
    // Non-decreasing; two equal times are a contact (one pose, two velocities), never at the
    // first or last key, never two in a row.
    let last = tr.key_count() - 1;
    for k in 0..last {
        let (a, b) = (tr.times[k], tr.times[k + 1]);
        let contact = a == b && k > 0 && k + 1 < last && tr.times[k - 1] < a && b < tr.times[k + 2] && tr.positions[k] == tr.positions[k + 1];
        if !(a < b || contact) {
            return bad(format!("key times are not increasing at key {} (equal times are a contact only between other keys, with one pose)", k + 1));
        }
    }
    for (what, keys) in [("positions", &tr.positions), ("velocities", &tr.velocities)] {
        for (k, key) in keys.iter().enumerate() {
            if key.len() != n {
                return bad(format!("key {k} has {} {what} but the mesh has {n} vertices", key.len()));
            }
            if let Some(v) = key.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
                return bad(format!("has a non-finite {what} value at key {k}, vertex {v}"));
            }
        }
    }
    if tr.frames(animation.scene.fps).is_empty() {
        return Err(Error::general(
            format!("cannot export: the animation runs from {} s to {} s, between two frames at {} fps", tr.start(), tr.end(), animation.scene.fps),
            "give the keys a time range that contains a frame, or raise fps",
        ));
    }
    if animation.mesh.triangles.is_empty() {
        return bad("mesh has no triangles".into());
    }
    if let Some(t) = animation.mesh.triangles.iter().position(|t| t.iter().any(|&i| i as usize >= n)) {
        return bad(format!("mesh triangle {t} uses a vertex index beyond its {n} vertices"));
    }
    if let Some(Err(problem)) = animation.mesh.attributes.as_ref().map(|a| a.check(animation.mesh.triangles.len())) {
        return bad(format!("mesh {problem}"));
    }
    Ok(())
}
