//! Grids, integer indices and the one coordinate convention of volcap.
//!
//! # Coordinate convention (the only one; everything else converts to it)
//!
//! * Space is the **normalized device coordinates (NDC) of the render view**, the cube
//!   `[-1, 1]^3`:
//!   - `x` runs left to right across the image (column),
//!   - `y` runs **top to bottom** down the image (row), as in image memory and in PyTorch's
//!     `grid_sample` (`y = -1` is the top row),
//!   - `z` runs along the camera ray, **larger z is nearer the camera** (`z = +1` is the
//!     front face of the volume, `z = -1` the back).
//!
//!   The frame is therefore left-handed; nothing in the engine relies on handedness except
//!   the renderer, which looks down `-z`.
//! * A grid of level `L` has `n = 2^L + 1` points per axis. Points are addressed by **integer
//!   indices** `[i, j, k]` in `0..n` of the *finest* grid, never by float indices. A point's
//!   NDC position is `-1 + 2 * index / (n - 1)` on every axis ("align corners": index 0 is
//!   exactly -1, index n-1 exactly +1; there is no half-voxel offset anywhere, geometry and
//!   colour alike). [`GridSpec::world`] and [`GridSpec::index_of`] are the round trip.
//! * A coarser level `l < L` uses the points whose indices are multiples of the stride
//!   `2^(L - l)`; every fine point is the exact mean of 1, 2, 4 or 8 coarse parents.
//! * Linear storage is `x` fastest: `linear = i + n * (j + n * k)`.
//! * The iso level is [`ISO`] = 0.5, and a value is **inside** iff `value > ISO`
//!   ([`is_inside`]): one source of truth for every method, metric and mesher.

use glam::Vec3;

/// The occupancy iso level. Every method, metric and mesher uses this constant.
pub const ISO: f32 = 0.5;

/// The binarization rule: inside iff strictly above [`ISO`].
#[inline]
pub fn is_inside(v: f32) -> bool {
    v > ISO
}

/// Largest supported level (1025^3 points; linear indices still fit in `u32`).
pub const MAX_LEVEL: u32 = 10;

/// Errors in grid specifications.
#[derive(Debug, Clone, thiserror::Error, PartialEq, Eq)]
pub enum GridError {
    #[error(
        "grid resolution {0} is not of the form 2^L + 1 with 1 <= L <= {MAX_LEVEL} (e.g. 65, 129, 257, 513)"
    )]
    BadResolution(usize),
    #[error("coarsest level {coarse} must be between 1 and the finest level {fine}")]
    BadCoarseLevel { coarse: u32, fine: u32 },
}

/// A grid of `2^level + 1` points per axis over NDC `[-1, 1]^3`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GridSpec {
    level: u32,
    n: usize,
    /// `u64::MAX / n + 1`: division by `n` as a multiplication ([`div_n`]).
    n_magic: u64,
}

/// `(q / n, q % n)` for any u32 `q`, with `magic = u64::MAX / n + 1` (Lemire, Kaser and
/// Kurz, "Faster remainder by direct computation", 2019: exact for every 32-bit numerator
/// and divisor): two multiplications instead of a division.
#[inline]
fn div_n(q: u32, n: u32, magic: u64) -> (u32, u32) {
    let d = ((magic as u128 * q as u128) >> 64) as u32;
    (d, q - d * n)
}

impl GridSpec {
    /// A grid of level `level` (`2^level + 1` points per axis).
    pub fn new(level: u32) -> Result<Self, GridError> {
        if level == 0 || level > MAX_LEVEL {
            return Err(GridError::BadResolution((1usize << level.min(31)) + 1));
        }
        let n = (1usize << level) + 1;
        Ok(Self {
            level,
            n,
            n_magic: u64::MAX / n as u64 + 1,
        })
    }

    /// The grid with `resolution` points per axis; `resolution` must be `2^L + 1`.
    pub fn from_resolution(resolution: usize) -> Result<Self, GridError> {
        let m = resolution.wrapping_sub(1);
        if resolution < 3 || !m.is_power_of_two() {
            return Err(GridError::BadResolution(resolution));
        }
        let level = m.trailing_zeros();
        if level > MAX_LEVEL {
            return Err(GridError::BadResolution(resolution));
        }
        Self::new(level)
    }

    pub fn level(&self) -> u32 {
        self.level
    }

    /// Points per axis.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Total number of points (`n^3`).
    pub fn len(&self) -> usize {
        self.n * self.n * self.n
    }

    pub fn is_empty(&self) -> bool {
        false
    }

    /// Spacing between neighbouring points in NDC units.
    pub fn spacing(&self) -> f32 {
        2.0 / (self.n - 1) as f32
    }

    /// The grid one level coarser (`None` at level 1).
    pub fn coarser(&self) -> Option<GridSpec> {
        GridSpec::new(self.level - 1).ok()
    }

    /// Stride, in this grid's indices, of the points of level `l <= self.level`.
    #[inline]
    pub fn stride(&self, l: u32) -> usize {
        1usize << (self.level - l)
    }

    #[inline]
    pub fn linear(&self, [i, j, k]: [usize; 3]) -> usize {
        i + self.n * (j + self.n * k)
    }

    #[inline]
    pub fn unlinear(&self, idx: usize) -> [usize; 3] {
        // In u32 (faster divisions): every grid has fewer than 2^32 points (1025^3 at most).
        debug_assert!(idx < self.len());
        let (n, q) = (self.n as u32, idx as u32);
        let (r, i) = div_n(q, n, self.n_magic);
        let (k, j) = div_n(r, n, self.n_magic);
        [i as usize, j as usize, k as usize]
    }

    /// NDC coordinate of index `i` along any axis.
    #[inline]
    pub fn coord(&self, i: usize) -> f32 {
        // Computed as (2i - (n-1)) / (n-1): exact for the end points and symmetric.
        let m = (self.n - 1) as f32;
        (2.0 * i as f32 - m) / m
    }

    /// NDC position of a grid point.
    #[inline]
    pub fn world(&self, [i, j, k]: [usize; 3]) -> Vec3 {
        Vec3::new(self.coord(i), self.coord(j), self.coord(k))
    }

    /// The grid point nearest to an NDC position, or `None` outside `[-1, 1]^3` or for
    /// non-finite input. Round trip: `index_of(world(idx)) == Some(idx)`.
    pub fn index_of(&self, p: Vec3) -> Option<[usize; 3]> {
        let m = (self.n - 1) as f32;
        let mut out = [0usize; 3];
        for (o, c) in out.iter_mut().zip(p.to_array()) {
            if !c.is_finite() || !(-1.0..=1.0).contains(&c) {
                return None;
            }
            let f = ((c + 1.0) * 0.5 * m).round();
            *o = (f as usize).min(self.n - 1);
        }
        Some(out)
    }
}

/// A fixed-size bitset over grid points (one bit per point, not a bool volume).
#[derive(Debug, Clone, Default)]
pub struct BitSet {
    words: Vec<u64>,
    len: usize,
}

impl BitSet {
    pub fn new(len: usize) -> Self {
        Self {
            words: vec![0; len.div_ceil(64)],
            len,
        }
    }

    /// Resize to `len` bits, all cleared; keeps the allocation when it is large enough.
    pub fn reset(&mut self, len: usize) {
        let w = len.div_ceil(64);
        self.words.clear();
        self.words.resize(w, 0);
        self.len = len;
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    #[inline]
    pub fn get(&self, i: usize) -> bool {
        (self.words[i >> 6] >> (i & 63)) & 1 == 1
    }

    /// Whether every bit of `mask` (at most 8 bits wide) is set in the bits from `i` on:
    /// bit `b` of `mask` stands for bit `i + b`. One or two word reads.
    #[inline]
    pub fn all_set(&self, i: usize, mask: u64) -> bool {
        let (w, b) = (i >> 6, i & 63);
        let mut bits = self.words[w] >> b;
        if b > 56 {
            bits |= self.words.get(w + 1).map_or(0, |x| x << (64 - b));
        }
        bits & mask == mask
    }

    #[inline]
    pub fn set(&mut self, i: usize) {
        self.words[i >> 6] |= 1u64 << (i & 63);
    }

    /// Sets bit `i`; returns true if it was clear before.
    #[inline]
    pub fn insert(&mut self, i: usize) -> bool {
        let w = &mut self.words[i >> 6];
        let m = 1u64 << (i & 63);
        let was = *w & m != 0;
        *w |= m;
        !was
    }

    #[inline]
    pub fn clear_bit(&mut self, i: usize) {
        self.words[i >> 6] &= !(1u64 << (i & 63));
    }

    pub fn count_ones(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// The raw 64-bit words (bit `i` of the set is bit `i % 64` of word `i / 64`).
    pub fn iter_ones_words(&self) -> impl Iterator<Item = u64> + '_ {
        self.words.iter().copied()
    }

    /// Call `f` on the index of every set bit (ascending) and clear them all, writing only
    /// the words that held a bit.
    pub fn drain_ones(&mut self, mut f: impl FnMut(usize)) {
        for (wi, w) in self.words.iter_mut().enumerate() {
            let mut bits = *w;
            if bits == 0 {
                continue;
            }
            while bits != 0 {
                f(wi * 64 + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
            *w = 0;
        }
    }

    /// Indices of the set bits, ascending.
    pub fn iter_ones(&self) -> impl Iterator<Item = usize> + '_ {
        self.words.iter().enumerate().flat_map(|(wi, &w)| {
            let mut w = w;
            std::iter::from_fn(move || {
                if w == 0 {
                    return None;
                }
                let b = w.trailing_zeros() as usize;
                w &= w - 1;
                Some(wi * 64 + b)
            })
        })
    }
}

/// The result type of every localization method: a value for every point of the finest
/// grid plus which points were actually evaluated by the field.
///
/// Values at unevaluated points are whatever the method defines (interpolated, filled);
/// `evaluated` says which values came from the field. Buffers are reused across frames.
#[derive(Debug, Clone)]
pub struct Grid {
    spec: GridSpec,
    pub values: Vec<f32>,
    pub evaluated: BitSet,
    /// A box holding every unevaluated point whose value may be non-zero (`None`: unknown,
    /// anywhere). Kept by the sparse methods (see [`Grid::reset_sparse`]).
    written: Option<IndexBox>,
    /// Within `written`, per row `j + n k` the x span `[lo, hi]` holding its written points
    /// (`lo > hi`: none; [`Grid::written_spans`]).
    spans: Vec<[u32; 2]>,
}

/// A row span holding nothing.
pub const NO_SPAN: [u32; 2] = [u32::MAX, 0];

impl Default for IndexBox {
    fn default() -> Self {
        Self::EMPTY
    }
}

/// An axis-aligned box of integer grid indices, bounds inclusive; empty when any `lo > hi`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IndexBox {
    pub lo: [usize; 3],
    pub hi: [usize; 3],
}

impl IndexBox {
    pub const EMPTY: IndexBox = IndexBox {
        lo: [usize::MAX; 3],
        hi: [0; 3],
    };

    pub fn is_empty(&self) -> bool {
        (0..3).any(|a| self.lo[a] > self.hi[a])
    }

    /// Grow to hold `p`.
    #[inline]
    pub fn add(&mut self, p: [usize; 3]) {
        for (a, v) in p.into_iter().enumerate() {
            self.lo[a] = self.lo[a].min(v);
            self.hi[a] = self.hi[a].max(v);
        }
    }

    pub fn union(&self, o: &IndexBox) -> IndexBox {
        if self.is_empty() {
            return *o;
        }
        if o.is_empty() {
            return *self;
        }
        IndexBox {
            lo: std::array::from_fn(|a| self.lo[a].min(o.lo[a])),
            hi: std::array::from_fn(|a| self.hi[a].max(o.hi[a])),
        }
    }

    /// Grown by `pad` on every side, then outward to multiples of `align`, within `0..n`.
    pub fn padded(&self, pad: usize, align: usize, n: usize) -> IndexBox {
        if self.is_empty() {
            return *self;
        }
        IndexBox {
            lo: self.lo.map(|v| v.saturating_sub(pad) / align * align),
            hi: self
                .hi
                .map(|v| ((v + pad).div_ceil(align) * align).min(n - 1)),
        }
    }
}

impl Grid {
    pub fn new(spec: GridSpec) -> Self {
        Self {
            spec,
            values: vec![0.0; spec.len()],
            evaluated: BitSet::new(spec.len()),
            written: Some(IndexBox::EMPTY),
            spans: vec![NO_SPAN; spec.n() * spec.n()],
        }
    }

    /// Re-target the grid to `spec`, clearing `evaluated`. Keeps allocations; values are
    /// left as they are (the method then writes every value).
    pub fn reset(&mut self, spec: GridSpec) {
        self.spec = spec;
        self.values.resize(spec.len(), 0.0);
        self.evaluated.reset(spec.len());
        self.written = None;
    }

    /// Re-target the grid to `spec` with every value 0.0 and nothing evaluated, at the cost
    /// of what the previous frame wrote (its evaluated points and each row's written span)
    /// when the grid was last filled by a sparse method, of the whole volume otherwise. A
    /// sparse method then writes values only where they are non-zero and reports where
    /// ([`Grid::written_spans`]).
    pub fn reset_sparse(&mut self, spec: GridSpec) {
        match self.written {
            Some(b)
                if spec == self.spec
                    && self.values.len() == spec.len()
                    && self.evaluated.len() == spec.len()
                    && self.spans.len() == spec.n() * spec.n() =>
            {
                // Clears `evaluated` too, touching only its non-zero words.
                let values = &mut self.values;
                self.evaluated.drain_ones(|i| values[i] = 0.0);
                let n = spec.n();
                if !b.is_empty() {
                    for k in b.lo[2]..=b.hi[2] {
                        for j in b.lo[1]..=b.hi[1] {
                            let id = j + n * k;
                            let [lo, hi] = std::mem::replace(&mut self.spans[id], NO_SPAN);
                            if lo <= hi {
                                let (lo, hi) = (lo as usize, hi as usize);
                                self.values[n * id + lo..=n * id + hi].fill(0.0);
                            }
                        }
                    }
                }
            }
            _ => {
                self.values.clear();
                self.values.resize(spec.len(), 0.0);
                self.evaluated.reset(spec.len());
                self.spans.clear();
                self.spans.resize(spec.n() * spec.n(), NO_SPAN);
            }
        }
        self.spec = spec;
        self.written = Some(IndexBox::EMPTY);
    }

    /// For a sparse method about to write unevaluated values inside `b`: the values, and per
    /// row `j + n k` the span of its written points, which the caller widens to hold every
    /// point it writes in that row, inside `b` (so that [`Grid::reset_sparse`] clears only
    /// those).
    pub fn written_spans(&mut self, b: IndexBox) -> (&mut [f32], &mut [[u32; 2]]) {
        if let Some(w) = &mut self.written {
            *w = w.union(&b);
        }
        (&mut self.values, &mut self.spans)
    }

    pub fn spec(&self) -> GridSpec {
        self.spec
    }

    #[inline]
    pub fn value(&self, idx: [usize; 3]) -> f32 {
        self.values[self.spec.linear(idx)]
    }

    #[inline]
    pub fn inside(&self, linear: usize) -> bool {
        is_inside(self.values[linear])
    }

    /// Number of points whose value came from the field.
    pub fn evaluated_count(&self) -> usize {
        self.evaluated.count_ones()
    }

    /// The binarized grid as a bitset (inside = 1).
    pub fn binarized(&self) -> BitSet {
        let mut b = BitSet::new(self.spec.len());
        for (i, &v) in self.values.iter().enumerate() {
            if is_inside(v) {
                b.set(i);
            }
        }
        b
    }
}

/// Offsets of the 26-neighbourhood (3x3x3 minus the centre).
pub const RING26: [[i32; 3]; 26] = {
    let mut out = [[0i32; 3]; 26];
    let mut c = 0;
    let mut k = -1;
    while k <= 1 {
        let mut j = -1;
        while j <= 1 {
            let mut i = -1;
            while i <= 1 {
                if !(i == 0 && j == 0 && k == 0) {
                    out[c] = [i, j, k];
                    c += 1;
                }
                i += 1;
            }
            j += 1;
        }
        k += 1;
    }
    out
};

/// `idx + off * stride`, or `None` when it leaves `0..n`.
#[inline]
pub fn offset(idx: [usize; 3], off: [i32; 3], stride: usize, n: usize) -> Option<[usize; 3]> {
    let mut out = [0usize; 3];
    for a in 0..3 {
        let v = idx[a] as i64 + off[a] as i64 * stride as i64;
        if v < 0 || v >= n as i64 {
            return None;
        }
        out[a] = v as usize;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `all_set` agrees with bit-by-bit tests at every offset, across word boundaries and at
    /// the set's last word.
    #[test]
    fn all_set_agrees_with_each_bit() {
        let len = 200;
        let mut b = BitSet::new(len);
        for i in (0..len).filter(|i| i % 7 != 3 && i % 11 != 5) {
            b.set(i);
        }
        for i in 0..len - 3 {
            for mask in [0b1u64, 0b101, 0b111, 0b110] {
                let want = (0..3).all(|x| mask >> x & 1 == 0 || b.get(i + x));
                assert_eq!(b.all_set(i, mask), want, "at {i} mask {mask:b}");
            }
        }
    }

    #[test]
    fn unlinear_by_multiplication_equals_division() {
        for level in 1..=MAX_LEVEL {
            let spec = GridSpec::new(level).unwrap();
            let n = spec.n();
            let len = spec.len();
            // Every index of the small grids; the first, last and a stride of the large ones.
            let step = (len / 200_000).max(1);
            for idx in (0..len).step_by(step).chain([len - 1, len / 2 + 1]) {
                assert_eq!(
                    spec.unlinear(idx),
                    [idx % n, (idx / n) % n, idx / (n * n)],
                    "n {n} idx {idx}"
                );
            }
        }
        // The divisor trick holds for every u32 numerator (edges of the range).
        for n in [3u32, 5, 9, 17, 33, 65, 129, 257, 513, 1025] {
            let m = u64::MAX / n as u64 + 1;
            for q in [
                0u32,
                1,
                n - 1,
                n,
                n + 1,
                u32::MAX - 1,
                u32::MAX,
                0x8000_0000,
                123_456_789,
            ] {
                assert_eq!(div_n(q, n, m), (q / n, q % n), "{q} / {n}");
            }
        }
    }

    #[test]
    fn resolution_forms() {
        assert_eq!(GridSpec::from_resolution(257).unwrap().level(), 8);
        assert_eq!(GridSpec::from_resolution(3).unwrap().level(), 1);
        assert!(GridSpec::from_resolution(256).is_err());
        assert!(GridSpec::from_resolution(0).is_err());
        assert!(GridSpec::from_resolution(2).is_err());
        assert!(GridSpec::from_resolution((1 << 11) + 1).is_err());
    }

    #[test]
    fn end_points_are_exact() {
        let g = GridSpec::new(8).unwrap();
        assert_eq!(g.coord(0), -1.0);
        assert_eq!(g.coord(256), 1.0);
        assert_eq!(g.coord(128), 0.0);
    }

    #[test]
    fn coarse_points_coincide_with_fine_points() {
        let fine = GridSpec::new(7).unwrap();
        let coarse = GridSpec::new(5).unwrap();
        for i in 0..coarse.n() {
            assert_eq!(coarse.coord(i), fine.coord(i * fine.stride(5)));
        }
    }

    #[test]
    fn ring_has_26_distinct_offsets() {
        let mut v: Vec<_> = RING26.to_vec();
        v.sort();
        v.dedup();
        assert_eq!(v.len(), 26);
        assert!(!v.contains(&[0, 0, 0]));
    }

    #[test]
    fn bitset_ops() {
        let mut b = BitSet::new(130);
        assert!(b.insert(129));
        assert!(!b.insert(129));
        b.set(0);
        b.set(64);
        assert_eq!(b.iter_ones().collect::<Vec<_>>(), vec![0, 64, 129]);
        b.clear_bit(64);
        assert_eq!(b.count_ones(), 2);
    }
}
