//! Welding: the vertices of a frame source that coincide at every frame, merged into one.
//!
//! Exporters often write a vertex per triangle corner (a glTF skinned clip: 1728 vertices for
//! 290 points); every vertex then costs a column in the fit, a row in every blendshape target
//! and an entry in every file, for positions the others already hold. Vertices are merged only
//! when their positions are equal (exactly, `-0.0 == 0.0`) at every frame, so the welded
//! frames are the input's frames, and the input's numbering is kept in [`Weld::map`]: per
//! input vertex, its welded vertex. Per-corner attributes (UVs, normals, groups) stay on the
//! triangles' corners, so seams survive.

use super::FrameSource;
use crate::algorithms::geometry::Point;
use crate::support::error::Result;

/// Which input vertices are one welded vertex.
///
/// Invariants: `map.len()` is the input's vertex count; welded vertices are numbered by their
/// first input vertex, in input order (`first[map[v]] <= v`, `map[first[w]] == w`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Weld {
    /// Per input vertex, its welded vertex.
    pub map: Vec<u32>,
    /// Per welded vertex, the first input vertex it stands for.
    pub first: Vec<u32>,
}

/// A coordinate as a sortable key: `-0.0` and `0.0` are one position.
fn key(p: &Point) -> [u64; 3] {
    p.map(|x| if x == 0.0 { 0 } else { x.to_bits() })
}

impl Weld {
    /// The weld of `map` (per input vertex, its welded vertex, numbered as [`Weld`] says).
    pub(crate) fn from_map(map: Vec<u32>) -> Weld {
        let mut first = Vec::new();
        for (v, &w) in map.iter().enumerate() {
            if w as usize == first.len() {
                first.push(v as u32);
            }
        }
        Weld { map, first }
    }

    /// The vertices of `source` equal at every frame, found in one pass over its frames (the
    /// classes of frame 0 split at each frame where their members part).
    pub fn find(source: &mut dyn FrameSource) -> Result<Weld> {
        let n = source.vertex_count();
        let mut frame = vec![[0.0; 3]; n];
        // class[v]: a label shared by the vertices equal so far.
        let mut class: Vec<u32> = (0..n as u32).collect();
        let mut order: Vec<u32> = (0..n as u32).collect();
        for f in 0..source.frame_count() {
            source.read_frame(f, &mut frame)?;
            // Only vertices still sharing a class can split; after frame 0, the rest are done.
            if f > 0 {
                let mut size = vec![0u32; n];
                class.iter().for_each(|&c| size[c as usize] += 1);
                order.retain(|&v| size[class[v as usize] as usize] > 1);
                if order.is_empty() {
                    break;
                }
            } else {
                class.iter_mut().for_each(|c| *c = 0);
            }
            order.sort_unstable_by_key(|&v| (class[v as usize], key(&frame[v as usize])));
            // Relabel each run of equal (class, position) by its smallest member.
            let mut start = 0;
            while start < order.len() {
                let id = (class[order[start] as usize], key(&frame[order[start] as usize]));
                let end = start + order[start..].iter().take_while(|&&v| (class[v as usize], key(&frame[v as usize])) == id).count();
                let label = *order[start..end].iter().min().expect("a run has a member");
                for &v in &order[start..end] {
                    class[v as usize] = n as u32 + label;
                }
                start = end;
            }
            for &v in &order {
                class[v as usize] -= n as u32;
            }
        }
        // Number the classes by their first vertex, in input order.
        let mut number = vec![u32::MAX; n];
        let mut map = Vec::with_capacity(n);
        let mut count = 0u32;
        for &c in &class {
            if number[c as usize] == u32::MAX {
                number[c as usize] = count;
                count += 1;
            }
            map.push(number[c as usize]);
        }
        Ok(Weld::from_map(map))
    }

    /// Vertices after welding.
    pub fn len(&self) -> usize {
        self.first.len()
    }

    /// Whether there are no vertices.
    pub fn is_empty(&self) -> bool {
        self.first.is_empty()
    }

    /// Whether no two input vertices were merged.
    pub(crate) fn is_identity(&self) -> bool {
        self.first.len() == self.map.len()
    }

    /// Per-input-vertex values (positions of the input's numbering) on the welded vertices.
    pub fn pick<T: Clone>(&self, input: &[T]) -> Vec<T> {
        self.first.iter().map(|&v| input[v as usize].clone()).collect()
    }

    /// A mask of input vertices on the welded vertices: a welded vertex is in it when any of
    /// its input vertices is (they are one point at every frame).
    pub fn mask(&self, input: &[bool]) -> Vec<bool> {
        let mut out = vec![false; self.len()];
        for (v, &w) in self.map.iter().enumerate() {
            out[w as usize] |= input[v];
        }
        out
    }

    /// Triangles over input vertices, over the welded ones (same triangles, same corners).
    pub fn triangles(&self, triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
        triangles.iter().map(|t| t.map(|v| self.map[v as usize])).collect()
    }
}

/// A frame source read through a [`Weld`]: the welded vertices' positions.
pub(crate) struct Welded<S> {
    inner: S,
    weld: Weld,
    buffer: Vec<Point>,
}

impl<S: FrameSource> Welded<S> {
    /// `inner` (with the weld's input vertex count) on the welded vertices.
    pub fn new(inner: S, weld: Weld) -> Self {
        assert_eq!(inner.vertex_count(), weld.map.len(), "a weld of the source's vertices");
        let buffer = vec![[0.0; 3]; weld.map.len()];
        Welded { inner, weld, buffer }
    }
}

impl<S: FrameSource> FrameSource for Welded<S> {
    fn vertex_count(&self) -> usize {
        self.weld.len()
    }
    fn frame_count(&self) -> usize {
        self.inner.frame_count()
    }
    fn time(&self, frame: usize) -> f64 {
        self.inner.time(frame)
    }
    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        self.inner.read_frame(frame, &mut self.buffer)?;
        for (o, &v) in out.iter_mut().zip(&self.weld.first) {
            *o = self.buffer[v as usize];
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::frames::MemoryFrames;

    #[test]
    fn merges_only_what_coincides_at_every_frame() {
        // 0, 2 and 4 coincide at frame 0; 4 parts from them at frame 1; 1 and 3 coincide
        // throughout (3 with a -0.0).
        let frames = MemoryFrames {
            times: vec![0.0, 1.0],
            frames: vec![
                vec![[0.0; 3], [1.0, 2.0, 3.0], [0.0; 3], [1.0, 2.0, 3.0], [0.0; 3]],
                vec![[5.0, 0.0, 0.0], [1.0, 0.0, 3.0], [5.0, 0.0, 0.0], [1.0, -0.0, 3.0], [5.0, 0.0, 1.0]],
            ],
        };
        let weld = Weld::find(&mut frames.clone()).unwrap();
        assert_eq!(weld.map, vec![0, 1, 0, 1, 2]);
        assert_eq!(weld.first, vec![0, 1, 4]);
        assert_eq!(weld.mask(&[false, false, false, true, false]), vec![false, true, false]);
        assert_eq!(weld.triangles(&[[0, 1, 4], [2, 3, 4]]), vec![[0, 1, 2], [0, 1, 2]]);
        assert_eq!(Weld::from_map(weld.map.clone()), weld);
        let mut welded = Welded::new(frames, weld);
        let mut out = vec![[0.0; 3]; 3];
        welded.read_frame(1, &mut out).unwrap();
        assert_eq!(out, vec![[5.0, 0.0, 0.0], [1.0, 0.0, 3.0], [5.0, 0.0, 1.0]]);
    }

    #[test]
    fn distinct_vertices_are_the_identity() {
        let frames = MemoryFrames { times: vec![0.0], frames: vec![(0..50).map(|i| [i as f64, 0.0, 0.0]).collect()] };
        let weld = Weld::find(&mut frames.clone()).unwrap();
        assert!(weld.is_identity());
        assert_eq!(weld.map, (0..50).collect::<Vec<u32>>());
    }
}
