//! Column slabs: a wide frame computed as a few narrower ones, side by side, so that a layer's rows stay in
//! the core's L2 cache (a 24-channel f32 row of a 1080p frame is 180 KiB; of a 548-column slab, 51 KiB).
//!
//! Each slab is a full-height strip of frame columns `start .. start + width` that the plan runs as if it
//! were the whole frame (zero padding at its left and right edges), writing out only the columns it
//! `keep`s; the kept columns of the slabs tile the frame. A 3×3 layer computed with a wrong column at a slab
//! edge spoils the columns next to it: one column per direct layer, and up to a whole Winograd tile
//! (2 columns for F(2×2, 3×3), 4 for F(4×4, 3×3)) since a tile's rounding depends on every input column of it.
//! So every slab reaches `halo` (the sum over the layers of
//! [`KernelInfo::column_group`](tensorholo_kernels::KernelInfo::column_group)) columns past its kept columns, or to the
//! frame's edge, and starts at a multiple of 4 columns (the Winograd tiles of the frame and of the slab then
//! coincide): the kept columns are **bit-identical** with the whole frame's (tested). Slabs never reach past
//! the frame's edges (a layer would compute values there that the whole frame keeps at zero).
//!
//! All slabs have the same width, so one set of activation windows serves them one after the other.
//!
//! A layer need not compute a column that no kept column depends on: each slab's layers compute only the
//! columns the layers after them read ([`Slab::layers`], worked back from the kept columns: a layer's tiles
//! covering the columns the next layer reads, plus one column on each side for its own 3×3 reads). The first
//! layer computes nearly the whole slab, the last only the kept columns; every computed column is still the
//! whole frame's, since each tile computed reads only columns the layer before computed. At 1080p with four
//! slabs of the 8-layer network, its seven F(4×4, 3×3) layers compute 2,016 columns each on average where they
//! computed 2,176 (the whole slabs), and its last layer the 1,920 kept ones.

use std::ops::Range;

/// Columns of one slab: the frame columns `start .. start + width` it holds (`width` is the plan's
/// [`Slabs::width`]), the frame columns `keep` it writes out, and per layer the columns that layer computes
/// (`layers[i]`, slab columns, i.e. frame columns less `start`; empty: every layer the whole slab).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Slab {
    pub start: usize,
    pub keep: Range<usize>,
    pub layers: Vec<Range<usize>>,
}

impl Slab {
    /// The whole frame, `frame_width` columns, as one slab (every layer computes every column).
    pub(crate) fn whole(frame_width: usize) -> Self {
        Self {
            start: 0,
            keep: 0..frame_width,
            layers: Vec::new(),
        }
    }
}

/// The columns a pass over one slab reads and writes: the frame's width (the row stride of the input and
/// output planes) and the slab.
#[derive(Clone, Copy, Debug)]
pub(super) struct Cols<'a> {
    pub frame_width: usize,
    pub slab: &'a Slab,
}

/// How a plan cuts a frame of `frame_width` columns into slabs `width` columns wide.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Slabs {
    pub frame_width: usize,
    pub width: usize,
    pub slabs: Vec<Slab>,
}

impl Slabs {
    /// One slab: the whole frame.
    pub(crate) fn whole(frame_width: usize) -> Self {
        Self {
            frame_width,
            width: frame_width,
            slabs: vec![Slab::whole(frame_width)],
        }
    }

    /// `count` slabs (or fewer; one where they would not be narrower than the frame) of a frame
    /// `frame_width` columns wide for a network whose layers' tiles span `groups` columns each
    /// ([`KernelInfo::column_group`](tensorholo_kernels::KernelInfo::column_group), in layer order; their
    /// sum is the halo, see the module docs): the kept columns split near-equally at multiples of 4, every
    /// slab the same width, congruent to the frame's modulo 4, so that the last slab ends at the frame's edge
    /// and starts at a multiple of 4; each slab's layers compute the columns [`layer_columns`] gives.
    pub(crate) fn new(frame_width: usize, groups: &[usize], count: usize) -> Self {
        let halo = groups.iter().sum();
        // More slabs than multiples of 4 in the frame cannot have distinct starts: the whole frame (as the
        // check below would decide), without forming `count` bounds (`TENSORHOLO_SLABS` may be any integer).
        let count = if count > frame_width.div_ceil(4) {
            1
        } else {
            count.max(1)
        };
        let bounds: Vec<usize> = (0..=count)
            .map(|k| match k {
                0 => 0,
                k if k == count => frame_width,
                k => (k * frame_width / count) / 4 * 4,
            })
            .collect();
        let widest = bounds.windows(2).map(|b| b[1] - b[0]).max().unwrap_or(0);
        // Kept columns, the halo on both sides and 3 columns for rounding the starts down to a multiple of 4;
        // then up to the frame's width modulo 4.
        let mut width = widest + 2 * halo + 3;
        width += (frame_width + 4 - width % 4) % 4;
        if count == 1 || width >= frame_width || bounds.windows(2).any(|b| b[0] >= b[1]) {
            return Self::whole(frame_width);
        }
        let last_start = frame_width - width;
        let slabs = bounds
            .windows(2)
            .map(|b| {
                let start = (b[0].saturating_sub(halo) / 4 * 4).min(last_start);
                let keep = b[0]..b[1];
                Slab {
                    layers: layer_columns(groups, &keep, (start, width), frame_width),
                    start,
                    keep,
                }
            })
            .collect();
        Self {
            frame_width,
            width,
            slabs,
        }
    }

    /// How many slabs a plan of a frame `frame_width` columns wide, with hidden activations of `row_bytes`
    /// bytes per frame column (every channel) and spoiled columns reaching `halo`, uses: one where the
    /// frame's hidden row fits [`SLAB_MIN_ROW_BYTES`], else enough that a slab's fits [`SLAB_ROW_BYTES`],
    /// unless that recomputes (`2·halo` columns per slab boundary) more than an eighth of the frame: then
    /// one. `PlanRequest::slabs` replaces it (for benchmarks).
    pub(crate) fn count_for(frame_width: usize, row_bytes: usize, halo: usize) -> usize {
        let row = frame_width * row_bytes;
        if row <= SLAB_MIN_ROW_BYTES {
            return 1;
        }
        let count = row.div_ceil(SLAB_ROW_BYTES).max(1);
        // Slabs that would recompute more than an eighth of the frame do not pay (the 30-layer network at
        // 1080p, halo 120: two slabs ran 1.2× slower than one).
        if 8 * 2 * halo * (count - 1) > frame_width {
            return 1;
        }
        count
    }

    /// The slabs' columns, one after the other.
    pub(crate) fn iter(&self) -> impl Iterator<Item = &Slab> {
        self.slabs.iter()
    }
}

/// The columns each layer of a slab keeping frame columns `keep` computes, worked back from the last layer
/// (slab columns: frame columns less `start`): the last computes `keep`; a layer whose tiles span `g`
/// columns (`groups[i]`) computes the tiles covering the columns the layer after it reads (its own columns
/// and one on each side), `g`-aligned in frame columns and clipped to the frame (there the frame's zero
/// border is read, as in the whole frame). Each tile so computed reads only columns the layer before
/// computed, so it is the whole frame's tile, bit for bit. The first layer reads inside the slab
/// `start .. start + width` when the slab reaches the sum of `groups` past `keep` (or the frame's edge), as
/// [`Slabs::new`] places it; for a slab that does not, every layer computes the whole slab (empty result:
/// the spoiled columns then stay outside `keep` as the module docs say, given that reach).
pub(super) fn layer_columns(
    groups: &[usize],
    keep: &Range<usize>,
    (start, width): (usize, usize),
    frame_width: usize,
) -> Vec<Range<usize>> {
    let mut need = keep.clone();
    let mut layers = vec![0..0; groups.len()];
    for (cols, &g) in layers.iter_mut().zip(groups).rev() {
        let g = g.max(1);
        let (lo, hi) = (
            need.start / g * g,
            need.end.next_multiple_of(g).min(frame_width),
        );
        *cols = lo..hi;
        need = lo.saturating_sub(1)..(hi + 1).min(frame_width);
    }
    // The input columns the first layer reads (and so every layer's), inside the slab.
    if need.start < start || need.end > start + width {
        return Vec::new();
    }
    for cols in &mut layers {
        *cols = cols.start - start..cols.end - start;
    }
    layers
}

/// The most bytes a slab's widest activation row (every channel) should take: 48 KiB, 480 columns of a
/// 24-channel f32 network (holo8 at 1080p on Zen 5, four slabs against the whole frame: 394–404 against
/// 535–561 ms on one thread, 243–247 against 263–296 on two; benchmarks/history/BENCHMARKS-2026.md, "Column slabs").
pub(super) const SLAB_ROW_BYTES: usize = 48 << 10;

/// Frames whose widest activation row takes at most this many bytes (64 KiB) run as one slab: the
/// pre-filters' 8-channel rows at 1920 columns (60 KiB) ran faster whole (Zen 5, one thread: 127–129 ms
/// against 134 in two slabs).
pub(super) const SLAB_MIN_ROW_BYTES: usize = 64 << 10;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slabs_tile_the_frame_with_their_halo_inside_it() {
        for w in [
            97, 128, 383, 384, 511, 1000, 1917, 1918, 1919, 1920, 2001, 4096,
        ] {
            for groups in [
                vec![],
                vec![1],
                vec![1; 8],
                vec![2; 8],
                vec![4; 7],
                [vec![4; 7], vec![1]].concat(),
                [vec![1], vec![4; 6], vec![2]].concat(),
                vec![4; 30],
            ] {
                let halo: usize = groups.iter().sum();
                // Counts past the frame's multiples of 4 (any integer a setting gives): the whole frame.
                for count in [usize::div_ceil(w, 4) + 1, usize::MAX] {
                    assert_eq!(Slabs::new(w, &groups, count).slabs.len(), 1);
                }
                for count in 1..=6 {
                    let s = Slabs::new(w, &groups, count);
                    assert_eq!(s.frame_width, w);
                    // Kept columns tile 0..w in order.
                    let mut next = 0;
                    for slab in s.iter() {
                        assert_eq!(slab.keep.start, next, "w {w} halo {halo} count {count}");
                        assert!(slab.keep.end > slab.keep.start);
                        next = slab.keep.end;
                        // Inside the frame, a multiple of 4 from its start, the halo covered (or the edge).
                        assert!(slab.start + s.width <= w);
                        assert_eq!(slab.start % 4, 0, "{s:?}");
                        assert!(slab.start <= slab.keep.start.saturating_sub(halo));
                        let end = slab.start + s.width;
                        assert!(end >= (slab.keep.end + halo).min(w), "{s:?}");
                        if s.slabs.len() > 1 {
                            layers_read_only_what_the_layer_before_computed(
                                &groups, slab, s.width, w,
                            );
                        }
                    }
                    assert_eq!(next, w);
                    if s.slabs.len() > 1 {
                        assert!(s.width < w);
                        assert_eq!(s.width % 4, w % 4);
                        assert!(s.slabs.len() <= count);
                    } else {
                        assert_eq!(s, Slabs::whole(w));
                    }
                }
            }
        }
    }

    /// A slab's layer columns ([`layer_columns`]): the last layer computes the kept columns; each layer's
    /// first column is a multiple of its tile's columns in the frame (or the frame's edge), its tiles (the
    /// last one whole, unless at the frame's edge) read only columns the layer before computed (the input:
    /// the slab's) or the frame's zero border; and every layer computes fewer columns than the slab holds
    /// where the slab is narrower than keep + halo on a side inside the frame.
    fn layers_read_only_what_the_layer_before_computed(
        groups: &[usize],
        slab: &Slab,
        width: usize,
        frame_width: usize,
    ) {
        let at = format!("{groups:?} {slab:?} width {width}");
        assert_eq!(slab.layers.len(), groups.len(), "{at}");
        let frame = |r: &Range<usize>| r.start + slab.start..r.end + slab.start;
        if let Some(last) = slab.layers.last() {
            assert_eq!(frame(last), slab.keep, "{at}");
        }
        let mut before = slab.start..slab.start + width;
        for (cols, &g) in slab.layers.iter().zip(groups) {
            let c = frame(cols);
            assert!(c.start < c.end && c.end <= slab.start + width, "{at}");
            assert_eq!(c.start % g, 0, "{at}");
            let tiles_end = c.end.next_multiple_of(g);
            let reads = c.start.saturating_sub(1)..(tiles_end + 1).min(frame_width);
            assert!(
                before.start <= reads.start && reads.end <= before.end,
                "{at}: reads {reads:?}, the layer before computed {before:?}"
            );
            // A read at the frame's edge is the zero border, not a column.
            assert!(c.start > 0 || slab.start == 0, "{at}");
            before = c;
        }
        if slab.keep.start > 0 && slab.keep.end < frame_width && groups.len() > 1 {
            let first = &slab.layers[0];
            assert!(first.len() < width, "{at}");
        }
    }

    #[test]
    fn the_count_keeps_rows_small_and_the_recomputed_columns_few() {
        // holo8 at 1080p, 24 f32 channels, F(4×4, 3×3) everywhere (halo 32): 4 slabs of 480 kept columns.
        assert_eq!(Slabs::count_for(1920, 96, 32), 4);
        // At 384 columns, and the pre-filter's 8 channels at 1920: one.
        assert_eq!(Slabs::count_for(384, 96, 32), 1);
        assert_eq!(Slabs::count_for(1920, 32, 32), 1);
        // holo30 (halo 120): four slabs would recompute 37 % of the frame: one.
        assert_eq!(Slabs::count_for(1920, 96, 120), 1);
        // Direct layers only (halo 8): four.
        assert_eq!(Slabs::count_for(1920, 96, 8), 4);
    }
}
