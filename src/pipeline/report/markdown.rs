//! `report.md`: the report as Markdown tables.

use super::Report;
use crate::pipeline::scene::Format;
use crate::pipeline::stage_file::OutputKind;

/// The report as Markdown tables: a person reads it in a terminal or a merge request.
pub fn render(report: &Report) -> String {
    let mut s = String::new();
    let push = |s: &mut String, line: String| {
        s.push_str(&line);
        s.push('\n');
    };
    push(&mut s, format!("# blendsim report: {}\n", report.scene));
    push(&mut s, "| | |".into());
    push(&mut s, "|---|---|".into());
    let welded = report.input_vertices.map_or(String::new(), |n| format!(" (welded from {n})"));
    push(&mut s, format!("| surface | {} vertices{welded}, {} triangles |", report.vertices, report.faces));
    push(&mut s, format!("| body | {} tet nodes, {} tets |", report.tet_nodes, report.tets));
    if let Some(c) = &report.cage {
        push(
            &mut s,
            format!(
                "| cage | {} nodes ({} on its boundary, cubes of side {:.3e}) around {} vertices, because {}; keys reproduced to max {:.2e}, rms {:.2e} of the bbox diagonal |",
                c.nodes, c.boundary_nodes, c.spacing, c.fine_vertices, c.reason, c.key_error_max, c.key_error_rms
            ),
        );
    }
    for w in &report.warnings {
        push(&mut s, format!("| warning | {} |", w.replace('|', "/")));
    }
    push(
        &mut s,
        format!("| animation | {} keyframes, {:.3} s at {} fps ({} frames) |", report.keyframes, report.duration_s, report.fps, report.frames),
    );
    push(&mut s, format!("| basis | {} |", basis(report)));
    let sv = &report.solver;
    let (w0, w1) = (sv.energy.first().copied().unwrap_or(0.0), sv.energy.last().copied().unwrap_or(0.0));
    let change = if w0 > 0.0 { format!(" ({:+.1}%)", 100.0 * (w1 - w0) / w0) } else { String::new() };
    // W is at the configured samples; the coarse phase's iterations are counted apart.
    let coarse = if sv.coarse_iterations > 0 {
        format!(" ({} coarse at {} samples per interval + {} fine)", sv.coarse_iterations, sv.coarse_samples, sv.iterations - sv.coarse_iterations)
    } else {
        String::new()
    };
    push(
        &mut s,
        format!(
            "| solver | {}, {} iterations{coarse}, W {:.4e} -> {:.4e}{change}, {} |",
            sv.method,
            sv.iterations,
            w0,
            w1,
            if sv.converged { "converged" } else { "not converged" }
        ),
    );
    push(
        &mut s,
        format!(
            "| time | {:.3} s (precompute {:.3} s, {:.4} s per iteration, {} unknowns per coordinate) |",
            sv.seconds, sv.precompute_seconds, sv.iteration_seconds, sv.unknowns
        ),
    );
    if sv.method == crate::pipeline::scene::Method::Spacetime && sv.iterations > 0 {
        let remaining = sv.predicted_remaining.map_or("no prediction (the last two windows' decreases do not shrink)".to_string(), |r| {
            format!("predicted remaining decrease {:.3}%", 100.0 * r)
        });
        // W / S: the squared relative residual force (formats/scene.md, "When the solver stops").
        let scale = sv
            .force_scale
            .filter(|s| *s > 0.0)
            .map_or(String::new(), |s| format!("; W = {:.2e} S (S: the force scale)", sv.energy.last().copied().unwrap_or(0.0) / s));
        push(
            &mut s,
            format!("| convergence | W fell {:.3}% over the last iterations of the stopping window; {remaining}{scale} |", 100.0 * sv.last_decrease),
        );
    }
    if !sv.input_times.is_empty() && sv.times != sv.input_times {
        let list = |t: &[f64]| t.iter().map(|x| format!("{x:.4}")).collect::<Vec<_>>().join(", ");
        push(
            &mut s,
            format!(
                "| key times | optimized: {} s (input {} s; {} timing iterations, {} refactorizations) |",
                list(&sv.times),
                list(&sv.input_times),
                sv.timing_iterations,
                sv.refactorizations
            ),
        );
    }
    if let Some(c) = sv.conjugate_gradients {
        let capped = if c.capped > 0 {
            format!(
                "WARNING: {} stopped at the cap of {} iterations, relative residual up to {:.1e} (goal {:.0e})",
                c.capped, c.max_iterations, c.worst_residual, c.tolerance
            )
        } else {
            format!("all converged to a relative residual of {:.0e} (worst {:.1e})", c.tolerance, c.worst_residual)
        };
        push(
            &mut s,
            format!(
                "| global step | iterative (over the memory budget): {} CG solves, {:.1} iterations each on average; {capped} |",
                c.solves,
                c.iterations as f64 / c.solves.max(1) as f64
            ),
        );
    }
    if let Some(c) = sv.clearance {
        push(
            &mut s,
            format!(
                "| obstacles | smallest node clearance {c:.3e} over keys and frames, {} node-obstacle checks held at the end |",
                sv.active_contacts
            ),
        );
    }
    push(
        &mut s,
        format!(
            "| fidelity | max {:.2e}, rms {:.2e} of the bbox diagonal over {} frames ({}) |",
            report.error.max,
            report.error.rms,
            report.error.samples,
            // A cache bake's full-frame files are the cache: its error is in the Cache section.
            if report.cache.is_some() {
                "blendshape as stored vs the animation it stores; against the cache: below"
            } else {
                "blendshape vs full-frame"
            }
        ),
    );
    let quantized: Vec<String> = report.outputs.iter().filter_map(|f| f.quantization_error.map(|e| format!("{} {e:.2e}", f.path))).collect();
    if !quantized.is_empty() {
        push(&mut s, format!("| glb quantization | max {} of the bbox diagonal (read back from the files) |", quantized.join(", ")));
    }
    push(
        &mut s,
        format!(
            "| keyframes | moved up to {:.2e} (rms {:.2e}) of the bbox diagonal from the input |",
            report.keyframe_deviation.max, report.keyframe_deviation.rms
        ),
    );
    if let Some(v) = &report.volume {
        push(
            &mut s,
            format!(
                "| volume | {:.1}% to {:.1}% of rest, in-between loss {:.1}% (hermite baseline: {:.1}% to {:.1}%, loss {:.1}%) |",
                100.0 * v.animation.min,
                100.0 * v.animation.max,
                100.0 * v.animation.in_between_loss,
                100.0 * v.hermite.min,
                100.0 * v.hermite.max,
                100.0 * v.hermite.in_between_loss
            ),
        );
    }
    push(&mut s, String::new());
    // The fair ratio first: the full-frame file in the same format (and compression); then the
    // input as given, and the input's full-frame version (for a cache: the cache itself).
    let input = if report.cache.is_some() { "the cache" } else { "the keyframe files" };
    let full_input = if report.cache.is_some() { "the cache" } else { "full frame as f32 (PC2)" };
    push(&mut s, format!("| format | blendshape | full-frame, same format | smaller by | {input} | smaller by | {full_input} | smaller by |"));
    push(&mut s, "|---|---:|---:|---:|---:|---:|---:|---:|".into());
    let mut formats: Vec<Format> = report.outputs.iter().filter(|f| f.kind == OutputKind::Blendshape).map(|f| f.format).collect();
    formats.sort();
    formats.dedup();
    // An empty file has no ratio (see `size_ratios`).
    let ratio = |ratios: &std::collections::BTreeMap<Format, f64>, format| ratios.get(&format).map_or("n/a".to_string(), |r| format!("{r:.1}x"));
    for format in formats {
        let size = |kind| report.outputs.iter().find(|f| f.format == format && f.kind == kind).map(|f| f.bytes);
        let Some(blend) = size(OutputKind::Blendshape) else { continue };
        let full = size(OutputKind::FullFrame).map_or("not written".to_string(), human_bytes);
        push(
            &mut s,
            format!(
                "| {format} | {} | {full} | {} | {} | {} | {} | {} |",
                human_bytes(blend),
                ratio(&report.ratios, format),
                human_bytes(report.input_bytes),
                ratio(&report.input_ratios, format),
                human_bytes(report.full_frame_input_bytes),
                ratio(&report.full_frame_input_ratios, format)
            ),
        );
    }
    push(&mut s, String::new());
    push(&mut s, "| file | kind | bytes |".into());
    push(&mut s, "|---|---|---:|".into());
    for f in &report.outputs {
        let kind = match f.kind {
            OutputKind::Blendshape => "blendshape",
            OutputKind::FullFrame => "full-frame",
        };
        push(&mut s, format!("| {} | {kind} | {} |", f.path, f.bytes));
    }
    if let Some(c) = &report.cache {
        s.push_str(&super::cache_fit::markdown(c, &report.outputs));
    }
    s
}

/// The blendshape files' shapes as report.json's `basis` and `rank` say: `keys`, or
/// `principal, rank 3`.
pub fn basis(report: &Report) -> String {
    match (report.basis, report.rank) {
        (crate::pipeline::scene::Basis::Keys, _) => "keys".into(),
        (crate::pipeline::scene::Basis::Principal, Some(rank)) => format!("principal, rank {rank}"),
        (crate::pipeline::scene::Basis::Principal, None) => "principal".into(),
    }
}

/// `1.2 MB`, `45.3 KB`, `812 B` (decimal units, as file managers show).
pub(crate) fn human_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else if b >= 1e3 {
        format!("{:.1} KB", b / 1e3)
    } else {
        format!("{bytes} B")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn human_sizes() {
        assert_eq!(human_bytes(812), "812 B");
        assert_eq!(human_bytes(45_300), "45.3 KB");
        assert_eq!(human_bytes(8_600_000), "8.6 MB");
    }
}
