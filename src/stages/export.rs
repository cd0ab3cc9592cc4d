//! The `export` stage: the animation's blendshape and full-frame files.
//!
//! Contract: build the [`BlendShapeClip`] (blendshapes, in the form `[export] weights`
//! names) and the `FullFrame` (one pose per frame) from the animation, and stage, for each
//! format in `scene.export.formats`, `NAME.EXT` (blendshapes) and, when `full_frame`,
//! `NAME.full.EXT` (full-frame). `usdc` is converted from the staged `.usda` by usd-core.
//! Returns the list of staged files with their sizes. The files (and whatever the caller
//! stages after them, e.g. `NAME.outputs.json`) are in the staging group `export:NAME`: a
//! commit removes the files an earlier export of the same scene wrote that this one did not,
//! and keeps the report and other scenes' files. The layouts are specified in
//! `formats/usd.md` and `formats/gltf.md`.

use crate::error::{Error, Result};
use crate::export::clip::BlendShapeClip;
use crate::export::fullframe::FullFrame;
use crate::export::{glb, usda, usdc};
use crate::mesh::Axis;
use crate::output::Staging;
use crate::progress::Progress;
use crate::scene::{Format, GltfInterpolation};
use crate::stage::{Animation, OutputFile, OutputKind, Outputs};

/// Stage every requested file; `Outputs` lists them blendshapes first, then full-frame, each
/// in the order usda, usdc, glb, whatever order the scene file gives.
pub fn export(animation: &Animation, staging: &mut Staging) -> Result<Outputs> {
    export_with(animation, staging, None, &Progress::hidden())
}

/// [`export`] converting the `.usdc` files with `converter` (one started earlier, so that its
/// start-up overlapped other work) instead of a Python process started when the first is due,
/// and showing a bar over the files on `progress`.
pub fn export_with(animation: &Animation, staging: &mut Staging, converter: Option<usdc::Converter>, progress: &Progress) -> Result<Outputs> {
    check(animation)?;
    // One Python process for every usdc file of the export.
    let mut converter = converter;
    let scene = &animation.scene;
    staging.set_group(&format!("export:{}", scene.name));
    let trajectory = &animation.trajectory;
    let triangles = &animation.mesh.triangles;
    let attributes = animation.mesh.attributes.as_ref();
    let mut formats = scene.export.formats.clone();
    formats.sort();
    formats.dedup();
    let usd = usda::UsdSettings {
        name: usda::prim_name(&scene.name),
        fps: scene.fps,
        up_axis: if scene.export.up_axis == Axis::Z { 'Z' } else { 'Y' },
        meters_per_unit: scene.export.meters_per_unit,
    };
    let placement = glb::Placement { z_up: scene.export.up_axis == Axis::Z, meters_per_unit: scene.export.meters_per_unit };

    let clip = BlendShapeClip::new(trajectory, scene.export.weights);
    let full = scene.export.full_frame.then(|| FullFrame::from_trajectory(trajectory, scene.fps));
    let mut forms = vec![(OutputKind::Blendshape, String::new())];
    if full.is_some() {
        forms.push((OutputKind::FullFrame, ".full".into()));
    }

    let bar = progress.bar((forms.len() * formats.len()) as u64, "export");
    let mut files = Vec::new();
    for (kind, suffix) in forms {
        let stem = format!("{}{suffix}", scene.name);
        let usda_text = || match (&kind, &full) {
            (OutputKind::FullFrame, Some(full)) => usda::full_frame(full, triangles, attributes, &usd),
            _ => usda::blendshapes(&clip, triangles, attributes, &usd),
        };
        for &format in &formats {
            let name = format!("{stem}.{}", format.extension());
            bar.set_message(format!("export: {name}"));
            match format {
                Format::Usda => staging.write(&name, usda_text().as_bytes())?,
                Format::Usdc => {
                    // Formats are sorted, so a requested .usda is already staged; otherwise a
                    // hidden one is written for the conversion and not recorded as an output.
                    let source = if formats.contains(&Format::Usda) {
                        format!("{stem}.usda")
                    } else {
                        let temporary = format!(".{stem}.for-usdc.usda");
                        let path = staging.path(&temporary);
                        std::fs::write(&path, usda_text()).map_err(|e| Error::io(&path, &e, "write a temporary .usda"))?;
                        temporary
                    };
                    // Errors name the file the user asked for, not its staging path.
                    let converted = converter.get_or_insert_with(usdc::Converter::start).convert(&staging.path(&source), &staging.path(&name))
                        .map_err(|e| Error { path: Some(staging.final_path(&name)), ..e });
                    if source.starts_with('.') {
                        let _ = std::fs::remove_file(staging.path(&source));
                    }
                    converted?;
                    staging.record(&name);
                }
                Format::Glb => {
                    let bytes = match (&kind, &full) {
                        (OutputKind::FullFrame, Some(full)) => glb::full_frame(full, triangles, attributes, &scene.name, placement),
                        _ if scene.export.gltf_interpolation == GltfInterpolation::Linear => {
                            let frame_times: Vec<f64> = trajectory.frames(scene.fps).iter().map(|f| f.1).collect();
                            glb::blendshapes_sampled(&clip, &frame_times, triangles, attributes, &scene.name, placement)
                        }
                        _ => glb::blendshapes(&clip, triangles, attributes, &scene.name, placement),
                    };
                    staging.write(&name, &bytes)?;
                }
            }
            files.push(OutputFile { bytes: staging.size(&name)?, path: name, kind, format });
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    Ok(Outputs { files })
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
            format!(
                "cannot export: the animation runs from {} s to {} s, between two frames at {} fps",
                tr.start(),
                tr.end(),
                animation.scene.fps
            ),
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
