//! The bottom layer: what every other layer uses and that knows nothing of meshes or physics.
//!
//! - [`error`]: the one error type, whose message names the file, the problem and the fix;
//! - [`output`]: the output folder, staged and committed whole (never half-written);
//! - [`interrupt`]: clean interruption (signals, and the child processes to stop);
//! - [`progress`]: the progress bar and its quiet modes;
//! - [`budget`]: the memory and time a bake may use, a value passed down (no globals);
//! - [`input`]: bounded reading of input files;
//! - [`build_id`]: the build ID of an executable (what identifies the running blendsim).

pub mod budget;
pub mod build_id;
pub mod error;
pub mod input;
pub mod interrupt;
pub mod output;
pub mod progress;
#[cfg(test)]
pub(crate) mod testing;
