//! What a scene needs in memory: checked against the budget before anything that size is
//! allocated.

use super::Scene;
use crate::support::budget::Budget;
use crate::support::error::Result;

impl Scene {
    /// The memory the scene needs for the frames it exports (`vertices` exported vertices over
    /// the key times at the scene's fps) and the samples it solves (`tets`, or a lower bound
    /// before TetGen), checked against `budget` before anything that size is allocated.
    pub(crate) fn check_resources(&self, times: &[f64], vertices: usize, tets: usize, budget: &Budget) -> Result<()> {
        if let (Some(start), Some(end)) = (times.first(), times.last()) {
            budget.check_frames(*start, *end, self.fps, vertices, self.export.full_frame)?;
        }
        // Both methods evaluate W over the samples (`hermite` once, for the report).
        budget.check_samples(self.solver.samples, times.len().saturating_sub(1), tets)
    }

    /// The whole bake's estimated peak bytes with keys at `times` and these counts: the largest
    /// phase of `memory_model::phase_bytes` (what `--max-memory` refuses a bake over).
    pub fn memory_estimate(&self, times: &[f64], counts: &super::BakeCounts) -> f64 {
        super::memory_model::phase_bytes(self, times, counts).peak().1
    }
}
