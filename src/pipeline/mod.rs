//! The pipeline layer: the scene file, the data each stage writes, the stages, the report.
//!
//! - [`scene`]: the scene file a user writes (`formats/scene.md`);
//! - [`stage_file`]: the plain data that passes from one stage to the next (and between
//!   subcommands, as stage files);
//! - [`stages`]: one function per stage, and [`stages::bake()`] that runs the chain;
//! - [`report`]: the bake's report (JSON and Markdown) and the batch summary;
//! - [`depfile`]: the files a bake reads, as a Make depfile (`bake --depfile`).

pub mod depfile;
#[cfg(test)]
mod fuzz_readers;
pub mod report;
pub mod scene;
pub mod stage_file;
pub mod stages;
