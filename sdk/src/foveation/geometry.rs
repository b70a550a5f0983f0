//! [`TileGeometry`]: the hologram CNN's tile of a foveated frame — one size for every gaze (one CNN plan per
//! session), placed on the gaze and kept inside the frame.

use super::gaze::Gaze;

/// The fovea, its band and the hologram CNN's tile for `height × width` frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TileGeometry {
    /// The fovea's radius `R`, pixels.
    pub(crate) radius_px: f64,
    /// The blend band's width `B`, pixels.
    pub(crate) band_px: f64,
    /// The hologram CNN's receptive radius, pixels (one a 3 × 3 convolution).
    pub(crate) margin: usize,
    /// The tile's `(height, width)`: at most the frame's.
    pub(crate) tile: (usize, usize),
    /// The frame's `(height, width)`.
    pub(crate) frame: (usize, usize),
}

impl TileGeometry {
    /// The tile for a fovea of `radius_px`, a band of `band_px` and a CNN of receptive radius `margin` on
    /// `height × width` frames.
    ///
    /// The CNN's values are needed within `R + B` of the gaze: columns `⌊g − R − B⌋ ..= ⌈g + R + B⌉`, at most
    /// `2⌈R + B⌉ + 3` of them whatever the gaze's fraction, plus `margin` on each side, so that every pixel
    /// used is at least `margin` pixels inside the tile's edge (or the frame's: there the tile's zero padding
    /// is the frame's own).
    pub(crate) fn new(
        radius_px: f64,
        band_px: f64,
        margin: usize,
        height: usize,
        width: usize,
    ) -> Self {
        let reach = (radius_px + band_px).ceil();
        // Beyond the frame's size the tile is the frame: a saturating float-to-int cast keeps huge radii safe.
        let side = (2.0 * reach + 3.0) as usize;
        let side = side.saturating_add(2 * margin);
        Self {
            radius_px,
            band_px,
            margin,
            tile: (side.min(height), side.min(width)),
            frame: (height, width),
        }
    }

    /// The tile's top-left pixel `(y, x)` for `gaze`: its needed window starts `margin` pixels before the
    /// first column within `R + B` of the gaze, moved back inside the frame where it would cross an edge.
    pub(crate) fn origin(&self, gaze: &Gaze) -> (usize, usize) {
        let reach = self.radius_px + self.band_px;
        let place = |g: f64, side: usize, n: usize| {
            let start = (g - reach).floor() - self.margin as f64;
            let last = (n - side) as f64;
            start.clamp(0.0, last) as usize
        };
        (
            place(gaze.y, self.tile.0, self.frame.0),
            place(gaze.x, self.tile.1, self.frame.1),
        )
    }

    /// Whether the fovea (`r ≤ R`) holds every pixel centre of the frame: the farthest corner within `R`.
    pub(crate) fn covers_frame(&self, gaze: &Gaze) -> bool {
        let (h, w) = self.frame;
        let far = |g: f64, n: usize| g.abs().max((n as f64 - 1.0 - g).abs());
        far(gaze.x, w).hypot(far(gaze.y, h)) <= self.radius_px
    }

    /// The tile's share of the frame's pixels.
    pub(crate) fn share(&self) -> f64 {
        (self.tile.0 * self.tile.1) as f64 / (self.frame.0 * self.frame.1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gaze(x: f64, y: f64) -> Gaze {
        Gaze {
            x,
            y,
            depth_m: None,
        }
    }

    /// Every pixel within `R + B` of any gaze lies at least `margin` pixels inside the tile's edge, or the
    /// tile's edge is the frame's.
    #[test]
    fn the_tile_holds_the_band_and_its_margin_for_every_gaze() {
        for (r, b, m, h, w) in [
            (10.3, 4.0, 3, 64, 80),
            (0.0, 1.0, 8, 40, 40),
            (25.0, 16.0, 8, 90, 70),
            (500.0, 16.0, 30, 100, 120),
        ] {
            let g = TileGeometry::new(r, b, m, h, w);
            assert!(g.tile.0 <= h && g.tile.1 <= w);
            for gy in [
                -0.5,
                0.0,
                0.3,
                17.9,
                h as f64 / 2.0,
                h as f64 - 1.0,
                h as f64 - 0.5,
            ] {
                for gx in [-0.5, 0.49, 33.51, w as f64 - 0.5] {
                    let (oy, ox) = g.origin(&gaze(gx, gy));
                    assert!(oy + g.tile.0 <= h && ox + g.tile.1 <= w);
                    for y in 0..h {
                        for x in 0..w {
                            let d = (x as f64 - gx).hypot(y as f64 - gy);
                            if d >= r + b {
                                continue;
                            }
                            let inside = |p: usize, o: usize, side: usize, n: usize| {
                                p >= o
                                    && p < o + side
                                    && (p - o >= m || o == 0)
                                    && (o + side - 1 - p >= m || o + side == n)
                            };
                            assert!(
                                inside(y, oy, g.tile.0, h) && inside(x, ox, g.tile.1, w),
                                "R {r} B {b} m {m}: pixel ({y}, {x}) for gaze ({gy}, {gx}), tile at \
                                 ({oy}, {ox}) of {:?}",
                                g.tile
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn the_fovea_covers_the_frame_only_when_its_farthest_corner_is_within_r() {
        let g = TileGeometry::new(50.0, 16.0, 8, 60, 80);
        // The centre of a 60 × 80 frame: the corners are 49.65 pixels away.
        assert!(g.covers_frame(&gaze(39.5, 29.5)));
        assert!(!g.covers_frame(&gaze(0.0, 0.0)));
        let g = TileGeometry::new(49.0, 16.0, 8, 60, 80);
        assert!(!g.covers_frame(&gaze(39.5, 29.5)));
    }
}
