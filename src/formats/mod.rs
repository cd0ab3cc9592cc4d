//! The formats layer: every file blendsim reads or writes, and the TetGen program it runs.
//!
//! - [`mesh`]: keyframe meshes (OBJ, MEDIT, TetGen) and vertex selections;
//! - [`cache`]: vertex caches (OBJ sequences, PC2, MDD, glTF clips, USD point caches);
//! - [`export`]: USD (text and binary crate) and glTF writers, and their textures;
//! - [`tetgen`]: the external TetGen process, its input and output files;
//! - `child_script`: the Python child processes of the USD and Alembic readers, under `--max-time`.
//!
//! Readers and writers turn files into the types of [`crate::algorithms`] and back; each
//! format is specified in `formats/`.

pub mod cache;
pub(crate) mod child_script;
pub mod export;
pub mod mesh;
pub mod tetgen;
pub(crate) mod work_dir;
