//! `blendsim report --batch`: the `report.json` of many bakes in one table, `summary.csv`,
//! `summary.md` and `summary.html`, one row per bake.

use std::path::{Path, PathBuf};

use super::guard_rails::code_of;
use super::Report;
use crate::pipeline::scene::{Basis, Format};
use crate::pipeline::stage_file::OutputKind;
use crate::support::error::{Error, Result};

/// The `report.json` files of `dirs`: each folder's own, else those of its immediate
/// subfolders (a folder of bakes), in name order.
pub fn find_reports(dirs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut found = Vec::new();
    for dir in dirs {
        // Whatever is at a report's name is read as one: a folder or FIFO there is an error
        // naming it, not a bake silently left out.
        let own = dir.join("report.json");
        if own.exists() {
            found.push(own);
            continue;
        }
        let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, &e, "list the bake folders"))?;
        let mut inner: Vec<PathBuf> = entries.filter_map(|e| e.ok()).map(|e| e.path().join("report.json")).filter(|p| p.exists()).collect();
        if inner.is_empty() {
            return Err(Error::in_file(
                dir,
                "holds no report.json, nor do its subfolders",
                "pass bake output folders (blendsim bake --out DIR), or a folder of them",
            ));
        }
        inner.sort();
        found.extend(inner);
    }
    Ok(found)
}

/// Read one `report.json`.
pub fn read(path: &Path) -> Result<Report> {
    let bytes = crate::support::input::read_bytes(path, "a blendsim report")?;
    serde_json::from_slice(&bytes)
        .map_err(|e| Error::in_file(path, format!("is not a blendsim report ({e})"), "pass the report.json written by blendsim bake or report"))
}

const COLUMNS: [&str; 36] = [
    "bake",
    "scene",
    "method",
    "vertices",
    "tets",
    "keys",
    "frames",
    "basis",
    "rank",
    "cache_format",
    "cache_bytes",
    "usda_bytes",
    "full_usda_bytes",
    "usdc_bytes",
    "full_usdc_bytes",
    "glb_bytes",
    "full_glb_bytes",
    "usda_ratio",
    "usdc_ratio",
    "glb_ratio",
    "input_bytes",
    "usda_input_ratio",
    "glb_input_ratio",
    "full_input_bytes",
    "usda_full_input_ratio",
    "glb_full_input_ratio",
    "error_max",
    "error_rms",
    "converged",
    "iterations",
    "seconds",
    "key_movement",
    "volume_loss",
    "hermite_volume_loss",
    "fit_error_max",
    "warnings",
];

/// One row per report: `bake` is the folder holding it.
fn rows(reports: &[(PathBuf, Report)]) -> Vec<Vec<String>> {
    reports
        .iter()
        .map(|(path, r)| {
            let bytes = |format: Format, kind: OutputKind| {
                r.outputs.iter().find(|f| f.format == format && f.kind == kind).map_or(String::new(), |f| f.bytes.to_string())
            };
            let of = |ratios: &std::collections::BTreeMap<Format, f64>, format| ratios.get(&format).map_or(String::new(), |x| format!("{x:.2}"));
            let ratio = |format| of(&r.ratios, format);
            let (max, rms) = match &r.cache {
                Some(c) => (c.error.max, c.error.rms),
                None => (r.error.max, r.error.rms),
            };
            let cache = r.cache.as_ref();
            vec![
                path.parent().map_or(String::new(), |p| p.display().to_string()),
                r.scene.clone(),
                r.solver.method.to_string(),
                r.vertices.to_string(),
                r.tets.to_string(),
                r.keyframes.to_string(),
                r.frames.to_string(),
                match r.basis {
                    Basis::Keys => "keys".into(),
                    Basis::Principal => "principal".into(),
                },
                r.rank.map_or(String::new(), |k| k.to_string()),
                cache.map_or(String::new(), |c| c.format.clone()),
                cache.map_or(String::new(), |c| c.bytes.to_string()),
                bytes(Format::Usda, OutputKind::Blendshape),
                bytes(Format::Usda, OutputKind::FullFrame),
                bytes(Format::Usdc, OutputKind::Blendshape),
                bytes(Format::Usdc, OutputKind::FullFrame),
                bytes(Format::Glb, OutputKind::Blendshape),
                bytes(Format::Glb, OutputKind::FullFrame),
                ratio(Format::Usda),
                ratio(Format::Usdc),
                ratio(Format::Glb),
                r.input_bytes.to_string(),
                of(&r.input_ratios, Format::Usda),
                of(&r.input_ratios, Format::Glb),
                r.full_frame_input_bytes.to_string(),
                of(&r.full_frame_input_ratios, Format::Usda),
                of(&r.full_frame_input_ratios, Format::Glb),
                format!("{max:.3e}"),
                format!("{rms:.3e}"),
                r.solver.converged.to_string(),
                r.solver.iterations.to_string(),
                format!("{:.3}", r.solver.seconds),
                format!("{:.3e}", r.keyframe_deviation.max),
                r.volume.as_ref().map_or(String::new(), |v| format!("{:.4}", v.animation.in_between_loss)),
                r.volume.as_ref().map_or(String::new(), |v| format!("{:.4}", v.hermite.in_between_loss)),
                cache.and_then(|c| c.fit_error.as_ref()).map_or(String::new(), |f| format!("{:.3e}", f.max)),
                // The codes, one per warning (the lines are in the bake's report).
                r.warnings.iter().map(|w| code_of(w)).collect::<Vec<_>>().join(" "),
            ]
        })
        .collect()
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The columns `summary.html` sorts by.
const SORTABLE: [&str; 10] =
    ["usda_ratio", "usdc_ratio", "glb_ratio", "error_max", "error_rms", "seconds", "iterations", "key_movement", "volume_loss", "warnings"];

/// `summary.csv`, `summary.md` and `summary.html` of the reports (each with the path it was
/// read from), the last linking each bake's `report.html` relative to `out`, the folder the
/// summary is written to. `error_max`/`error_rms` are against the cache for a cache bake, else
/// the storage error.
pub fn summarize(reports: &[(PathBuf, Report)], out: &Path) -> (String, String, String) {
    let rows = rows(reports);
    let mut csv = COLUMNS.join(",") + "\n";
    let mut md = format!(
        "# blendsim batch summary: {} bakes\n\nerror: against the cache for cache bakes (relative to its bounding-box diagonal), else blendshape vs full-frame.\n\n| {} |\n|{}\n",
        rows.len(),
        COLUMNS.join(" | "),
        "---|".repeat(COLUMNS.len())
    );
    for row in &rows {
        csv += &(row.iter().map(|f| csv_field(f)).collect::<Vec<_>>().join(",") + "\n");
        md += &format!("| {} |\n", row.join(" | "));
    }
    let links: Vec<String> = reports.iter().map(|(path, _)| link(out, &path.with_file_name("report.html"))).collect();
    let html = super::html::summary(&COLUMNS, &rows, &links, &SORTABLE);
    (csv, md, html)
}

/// A link from a page in folder `from` to the file `to`: relative when both resolve (so the
/// folders can move together), else a `file://` URL; percent-encoded.
fn link(from: &Path, to: &Path) -> String {
    let absolute = |p: &Path| std::path::absolute(p).ok().map(|a| a.components().collect::<PathBuf>());
    let (Some(a), Some(b)) = (absolute(from), absolute(to)) else { return encode(&to.display().to_string()) };
    let common = a.components().zip(b.components()).take_while(|(x, y)| x == y).count();
    if common == 0 {
        return format!("file://{}", encode(&b.display().to_string()));
    }
    let mut rel: Vec<String> = a.components().skip(common).map(|_| "..".to_string()).collect();
    rel.extend(b.components().skip(common).map(|c| c.as_os_str().to_string_lossy().into_owned()));
    encode(&rel.join("/"))
}

/// Percent-encode what a URL path may not hold as is.
fn encode(path: &str) -> String {
    path.bytes().map(|b| if b.is_ascii_alphanumeric() || b"-._~/".contains(&b) { (b as char).to_string() } else { format!("%{b:02X}") }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_are_relative() {
        assert_eq!(link(Path::new("/a/summary"), Path::new("/a/bakes/one x/report.html")), "../bakes/one%20x/report.html");
        assert_eq!(link(Path::new("/a"), Path::new("/a/report.html")), "report.html");
    }
}
