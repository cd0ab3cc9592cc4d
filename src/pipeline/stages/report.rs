//! The `report` stage: measure an animation and the files exported from it.

use crate::algorithms::blendshape::clip::BlendShapeClip;
use crate::algorithms::geometry::{bbox_diagonal, surface};
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::pipeline::report::cache_fit::{cache_ratios, CacheReport};
use crate::pipeline::report::guard_rails::guard_rails;
use crate::pipeline::report::measures::{deviation, ratios_to, size_ratios, volume_range, StorageError};
use crate::pipeline::report::player::{self, ShownFrames};
use crate::pipeline::report::series::{energy_phases, ErrorSeries, KeyVolume, Series, VolumeSeries};
use crate::pipeline::report::{Report, Volume};
use crate::pipeline::scene::{Basis, Method};
use crate::pipeline::stage_file::CacheRecord;
use crate::pipeline::stage_file::{Animation, Outputs};
use crate::support::budget::Budget;
use crate::support::error::Result;

/// The report of an animation and the files exported from it (for a cache, measured against
/// the cache's frames, streamed again from it).
pub fn report(animation: &Animation, outputs: &Outputs, budget: &Budget) -> Result<Report> {
    let clip = super::export::blendshape_clip(animation, outputs.rank, budget)?;
    Ok(with_outputs(measure(animation, &clip, budget)?, outputs))
}

/// The report's measures of the animation alone, without the files (no outputs, no size
/// ratios): what takes time, so a bake measures while the files are written. [`with_outputs`]
/// completes it. `clip` is the blendshape clip the files hold and its rank
/// ([`super::export::blendshape_clip`]).
pub fn measure(animation: &Animation, clip: &(BlendShapeClip, Option<usize>), budget: &Budget) -> Result<Report> {
    let scene = &animation.scene;
    let tr = &animation.trajectory;
    let frames = tr.frames(scene.fps);
    let diagonal = bbox_diagonal(&animation.mesh.positions);
    // The clip the blendshape files hold (a principal one at the rank export chose).
    let (clip, rank) = (&clip.0, clip.1);
    // The input keys: every key of the trajectory, or every `stride`-th when it also holds
    // in-betweens (mass-spring: `inbetweens + 1`).
    let stride = ((tr.key_count() - 1) / animation.input_keys.len().saturating_sub(1).max(1)).max(1);
    let key_times: Vec<f64> = tr.times.iter().step_by(stride).copied().collect();
    let keyframe_deviation = deviation(tr.positions.iter().step_by(stride).cloned().zip(animation.input_keys.iter().cloned()), diagonal);
    let triangles = &animation.mesh.triangles;
    let closed = !triangles.is_empty() && surface::open_edges(&animation.mesh).is_empty();
    let rest_volume = surface::enclosed_volume(&animation.mesh.positions, triangles);
    let hermite = Trajectory::with_zero_velocities(key_times.clone(), animation.input_keys.clone());
    let measure_volume = closed && rest_volume > 0.0;
    // A principal clip plays its own trajectory: that is what the files hold.
    let played = rank.map(|_| clip.played(&tr.times));
    let played_tr = played.as_ref().unwrap_or(tr);
    // Every measure over the frames from one evaluation of each frame: the storage error, the
    // volumes, and the player's frames when the reference is the full-frame evaluation (a
    // cache bake's player shows the cache's frames, below).
    let mut storage = StorageError::new(clip, frames.len(), diagonal);
    let mut shown = animation.cache.is_none().then(|| ShownFrames::new(clip, triangles.len(), frames.len()));
    let (mut volume_a, mut volume_h) = (Vec::new(), Vec::new());
    for (f, &(_, t)) in frames.iter().enumerate() {
        let pose = tr.evaluate(t);
        storage.add(t, &pose);
        let show = shown.as_ref().is_some_and(|s| s.shows(f));
        let hermite_pose = if measure_volume || show { hermite.evaluate(t) } else { Vec::new() };
        if measure_volume {
            volume_a.push(surface::enclosed_volume(&pose, triangles));
            volume_h.push(surface::enclosed_volume(&hermite_pose, triangles));
        }
        if let Some(shown) = shown.as_mut().filter(|_| show) {
            let played_pose = played.as_ref().map(|p| p.evaluate(t));
            shown.add(&pose, played_pose.as_deref().unwrap_or(&pose), &hermite_pose);
        }
    }
    let (error, per_frame, per_frame_rms) = storage.finish();
    let volumes = measure_volume.then(|| {
        let (a, h) = (volume_a, volume_h);
        let volume = Volume {
            rest: rest_volume,
            animation: volume_range(tr, &frames, triangles, rest_volume, &a),
            hermite: volume_range(&hermite, &frames, triangles, rest_volume, &h),
        };
        let keys = key_times
            .iter()
            .zip(tr.positions.iter().step_by(stride).zip(&animation.input_keys))
            .map(|(&time, (a, i))| KeyVolume {
                time,
                animation: surface::enclosed_volume(a, triangles) / rest_volume,
                input: surface::enclosed_volume(i, triangles) / rest_volume,
            })
            .collect();
        let ratio = |v: Vec<f64>| v.into_iter().map(|x| x / rest_volume).collect();
        (volume, VolumeSeries { animation: ratio(a), hermite: ratio(h), keys })
    });
    let (volume, volume_series) = volumes.unzip();
    let cache = animation.cache.as_ref().map(|record| cache_report(animation, played_tr, record, budget)).transpose()?;
    let frame_times: Vec<f64> = frames.iter().map(|f| f.1).collect();
    // The player and the error series against the reference: the cache's frames for a cache
    // bake, else the full-frame evaluation.
    let (error_series, player) = match (&animation.cache, &cache) {
        (Some(record), Some(c)) => {
            let mut source = super::import_cache::reopen(record, budget)?;
            let times: Vec<f64> = (0..source.frames.frame_count()).map(|f| source.frames.time(f)).collect();
            let mut buffer = vec![[0.0; 3]; source.frames.vertex_count()];
            let player = player::build(
                "cache",
                clip,
                triangles,
                &times,
                |f| {
                    source.frames.read_frame(f, &mut buffer)?;
                    Ok(buffer.clone())
                },
                played_tr,
                &hermite,
                &key_times,
                c.error.diagonal,
            )?;
            let series = ErrorSeries { reference: "cache".into(), times, max: c.error.per_frame.clone(), rms: c.error.per_frame_rms.clone() };
            (series, player)
        }
        _ => {
            let shown = shown.expect("the player's frames of a bake without a cache");
            let player = shown.player("full-frame", clip, triangles, &frame_times, &key_times, if diagonal > 0.0 { diagonal } else { 1.0 });
            (ErrorSeries { reference: "full-frame".into(), times: frame_times.clone(), max: per_frame, rms: per_frame_rms }, player)
        }
    };
    let series = Series { frame_times, volume: volume_series, error: error_series, energy_phases: energy_phases(&animation.log) };
    Ok(Report {
        scene: scene.name.clone(),
        vertices: animation.counts.vertices,
        input_vertices: animation.weld_map().map(<[u32]>::len),
        faces: animation.counts.faces,
        tet_nodes: animation.counts.tet_nodes,
        tets: animation.counts.tets,
        keyframes: animation.counts.keyframes,
        largest_tet_volume: animation.counts.largest_tet_volume,
        max_volume: (scene.tet.max_volume > 0.0 && animation.counts.largest_tet_volume.is_some()).then_some(scene.tet.max_volume),
        duration_s: tr.duration(),
        fps: scene.fps,
        frames: frames.len(),
        solver: animation.log.clone(),
        outputs: Vec::new(),
        ratios: Default::default(),
        input_bytes: animation.input_bytes,
        input_ratios: Default::default(),
        full_frame_input_bytes: match &animation.cache {
            Some(record) => record.bytes,
            None => 32 + 12 * (animation.mesh.positions.len() * frames.len()) as u64,
        },
        full_frame_input_ratios: Default::default(),
        error,
        keyframe_deviation,
        volume,
        cache,
        cage: animation.cage.clone(),
        basis: if rank.is_some() { Basis::Principal } else { Basis::Keys },
        rank,
        warnings: animation.warnings.clone(),
        series: Some(series),
        player: Some(player),
    })
}

/// `report` (from [`measure`]) with the files of `outputs`, the size ratios they give, and the
/// guard rails' warnings after the stages' own.
pub fn with_outputs(mut report: Report, outputs: &Outputs) -> Report {
    report.outputs = outputs.files.clone();
    report.ratios = size_ratios(&outputs.files);
    report.input_ratios = ratios_to(report.input_bytes, &outputs.files);
    report.full_frame_input_ratios = ratios_to(report.full_frame_input_bytes, &outputs.files);
    if let Some(cache) = &mut report.cache {
        cache.ratios = cache_ratios(cache.bytes, &outputs.files);
    }
    let rails = guard_rails(&report);
    report.warnings.extend(rails);
    report
}

/// The cache part of the report: the animation the blendshape files play (`played`: the
/// trajectory of the exported surface, whose vertices are the cache's, or its principal clip)
/// against every cache frame, and for the simulated methods
/// the least-squares fit on the same keys and `fixed` constraints.
fn cache_report(animation: &Animation, played: &Trajectory, record: &CacheRecord, budget: &Budget) -> Result<CacheReport> {
    let error = super::import_cache::error_against(record, played, budget)?;
    let fit_error = match animation.log.method {
        Method::Fit => None,
        Method::Hermite | Method::Spacetime | Method::MassSpring => {
            let fit = super::import_cache::fit_cache(record, budget)?;
            Some(super::import_cache::error_against(record, &fit, budget)?.into())
        }
    };
    Ok(CacheReport {
        path: record.path.clone(),
        format: record.format.clone(),
        frames: record.frames,
        fps: record.fps,
        fps_source: record.fps_note.clone(),
        bytes: record.bytes,
        input_vertices: record.weld.as_ref().map_or(record.vertices, Vec::len),
        vertices: record.vertices,
        keys: record.keys.clone(),
        tolerance: record.tolerance,
        ratios: Default::default(),
        error: error.into(),
        fit_error,
    })
}
