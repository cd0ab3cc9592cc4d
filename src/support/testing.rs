//! Helpers shared by the unit tests of several modules: a deterministic random generator, the
//! paper's assets, and the test binary's measuring allocator ([`alloc`]). The small meshes are
//! the algorithms layer's (`algorithms::testing`): this layer knows no mesh type.

use std::path::{Path, PathBuf};

/// The one deterministic generator of the unit tests' random data: SplitMix64 (Steele, Lea and
/// Flood, 2014), whose every seed, 0 included, starts a well-mixed sequence.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `[lo, hi)`: the top 53 bits of [`Rng::next_u64`] as a fraction.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }

    /// Uniform in [-1, 1).
    pub fn next(&mut self) -> f64 {
        self.uniform(-1.0, 1.0)
    }

    /// A 3x3 matrix of [`Rng::next`] entries.
    pub fn mat(&mut self) -> [[f64; 3]; 3] {
        [[self.next(), self.next(), self.next()], [self.next(), self.next(), self.next()], [self.next(), self.next(), self.next()]]
    }
}

/// A file of the paper's scenes under `../shared/assets/paper`, or `None` (with a note)
/// when it is missing outside CI. With `CI=true` a missing asset fails the test.
pub fn paper_asset(rel: &str) -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/assets/paper").join(rel);
    if path.is_file() {
        return Some(path);
    }
    assert!(std::env::var("CI").as_deref() != Ok("true"), "test asset {} is missing (required when CI=true)", path.display());
    eprintln!("skipped: test asset {} is missing", path.display());
    None
}

pub mod alloc {
    //! The unit-test binary's global allocator: the system allocator, measuring what the current
    //! thread allocates while a probe runs. The fuzz tests of the readers bound two things with it:
    //! the largest single allocation (a header's counts must not turn into one huge buffer) and
    //! the peak of live bytes during a parse (a multiple of the input's size).

    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;

    thread_local! {
        /// Bytes this thread holds (allocated minus freed), since the thread started.
        static LIVE: Cell<isize> = const { Cell::new(0) };
        /// The most `LIVE` reached since the current [`peak`] began.
        static PEAK: Cell<isize> = const { Cell::new(0) };
        /// The largest single request since the current [`largest_allocation`] began.
        static LARGEST: Cell<usize> = const { Cell::new(0) };
    }

    /// `size` bytes requested (0 when freeing) and `delta` live bytes more.
    fn note(size: usize, delta: isize) {
        let _ = LIVE.try_with(|live| {
            let now = live.get() + delta;
            live.set(now);
            let _ = PEAK.try_with(|peak| peak.set(peak.get().max(now)));
        });
        let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
    }

    /// The system allocator, measuring.
    struct Meter;

    // SAFETY: every call is forwarded unchanged to the system allocator; the measuring touches
    // only const-initialised thread-locals (no allocation, no panic: `try_with`).
    unsafe impl GlobalAlloc for Meter {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            note(layout.size(), layout.size() as isize);
            unsafe { System.alloc(layout) }
        }

        unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
            note(layout.size(), layout.size() as isize);
            unsafe { System.alloc_zeroed(layout) }
        }

        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            note(new_size, new_size as isize - layout.size() as isize);
            unsafe { System.realloc(ptr, layout, new_size) }
        }

        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            note(0, -(layout.size() as isize));
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    #[global_allocator]
    static METER: Meter = Meter;

    /// Run `f` and return the largest single allocation it made on this thread.
    pub fn largest_allocation(f: impl FnOnce()) -> usize {
        LARGEST.with(|l| l.set(0));
        f();
        LARGEST.with(Cell::get)
    }

    /// Run `f` and return its result with the most bytes it held allocated at once on this
    /// thread (beyond what the thread held before).
    pub fn peak<R>(f: impl FnOnce() -> R) -> (R, usize) {
        let start = LIVE.with(Cell::get);
        PEAK.with(|p| p.set(start));
        let r = f();
        (r, (PEAK.with(Cell::get) - start).max(0) as usize)
    }

    #[test]
    fn the_meter_sees_allocations() {
        let largest = largest_allocation(|| {
            std::hint::black_box(vec![0u8; 123_456]);
        });
        assert!(largest >= 123_456);
        let (_, held) = peak(|| std::hint::black_box(vec![0u8; 4096]));
        assert!(held >= 4096);
    }
}
