//! The `[embed]` table: the surface carried on the body.

use serde::{Deserialize, Serialize};

/// The `[embed]` table.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Embed {
    /// A finer surface (OBJ, in the rest pose) to carry on the tet trajectory; by default the
    /// exported surface is the keyframe surface itself.
    #[serde(default)]
    pub surface: Option<String>,
}
