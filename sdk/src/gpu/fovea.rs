//! A foveated frame's midpoint hologram on the GPU (`docs/FOVEATION.md`; the CPU's
//! [`crate::foveation::Periphery::compose`]): the hologram CNN on the tile around the gaze only, then
//! `shaders/fovea.wgsl` — the band's phase per colour (a reduction on the GPU: no round trip to the CPU
//! between the tile's CNN and the blend) and the composed heads `[6, H, W]` (the tile's heads within `R`,
//! the blurred image at the band's phase beyond `R + B`, their linear blend between), written where the full
//! frame's CNN writes its heads. The session's frame then runs its stages after the heads as for a full frame.
//!
//! One plan for any gaze: the tile's size is fixed ([`GpuFoveaShape`]); a frame uploads the tile's CNN input,
//! the image and the gaze's numbers, and records the same dispatches.

use super::cnn::{GpuCnn, GpuStorage};
use super::context::GpuContext;
use super::kernel::{grid_1d, Kernel};
use super::shaders;
use crate::error::{invalid, HoloError, Result};
use crate::model::CnnWeights;

/// `Fovea` of `fovea.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FoveaParams {
    h: u32,
    w: u32,
    th: u32,
    tw: u32,
    oy: u32,
    ox: u32,
    groups: u32,
    max_hw: f32,
    gx: f32,
    gy: f32,
    gx_frac: f32,
    gy_frac: f32,
    r_in: f32,
    band: f32,
    gaze_depth: f32,
    scale_r: f32,
    scale_g: f32,
    scale_b: f32,
    _pad: [u32; 2],
}

/// The fovea of a session's foveated frames, in plain numbers (the pipeline's tile geometry).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GpuFoveaShape {
    /// The hologram CNN's tile `(T_h, T_w)`, at most the frame's.
    pub(crate) tile: (usize, usize),
    /// The fovea's radius `R`, pixels.
    pub(crate) radius_px: f64,
    /// The blend band's width `B`, pixels (> 0).
    pub(crate) band_px: f64,
    /// The blur's disc radius per unit of normalised depth difference, pixels, per colour: `κ·V·λ/(2p²)`.
    pub(crate) blur_px: [f64; 3],
    /// The largest box half-width of the blur (the CPU periphery's: a depth outside `[0, 1]` is clamped to it).
    pub(crate) max_half_width: f64,
}

/// One foveated frame's inputs ([`GpuFovea::upload`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct GpuFoveaFrame<'a> {
    /// The tile's CNN input: `C` planes of `T_h·T_w` values (packed as the frame's input is).
    pub(crate) tile: &'a [&'a [f32]],
    /// The frame's amplitude R, G, B after a calibration's intensity maps, `H·W` values each.
    pub(crate) amplitude: [&'a [f32]; 3],
    /// The frame's normalised depth, `H·W` values.
    pub(crate) depth: &'a [f32],
    /// The gaze point `(x, y)`, pixels.
    pub(crate) gaze: (f64, f64),
    /// The gaze's normalised depth.
    pub(crate) gaze_depth: f32,
    /// The tile's top-left pixel `(y, x)` (inside the frame).
    pub(crate) origin: (usize, usize),
}

/// The compose kernels of `fovea.wgsl` bound to a tile's heads, the image and the frame's heads.
#[derive(Debug)]
pub(crate) struct GpuCompose {
    shape: GpuFoveaShape,
    height: usize,
    width: usize,
    groups: usize,
    params: wgpu::Buffer,
    theta: wgpu::Buffer,
    band_sum: Kernel,
    band_phase: Kernel,
    compose: Kernel,
    binds: [wgpu::BindGroup; 3],
}

impl GpuCompose {
    /// Binds `tile` (f32 `[6, T_h, T_w]`), `image` (f32 `[4, H, W]`) and `heads` (f32 `[6, H, W]`, written).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a tile larger than the frame or empty, or a band that is
    /// not positive; [`HoloError::Gpu`].
    pub(crate) fn new(
        ctx: &GpuContext,
        shape: GpuFoveaShape,
        (height, width): (usize, usize),
        tile: &wgpu::Buffer,
        image: &wgpu::Buffer,
        heads: &wgpu::Buffer,
    ) -> Result<Self> {
        let (th, tw) = shape.tile;
        if th == 0 || tw == 0 || th > height || tw > width {
            return Err(invalid(
                "foveation",
                format!("a tile of {th}×{tw} on a {height}×{width} frame"),
            ));
        }
        if shape.band_px.is_nan() || shape.band_px <= 0.0 {
            return Err(invalid(
                "foveation",
                format!(
                    "the band must be wider than 0 pixels, got {}",
                    shape.band_px
                ),
            ));
        }
        let groups = (th * tw).div_ceil(256).clamp(1, 1024);
        let params = ctx.uniform("fovea", &<FoveaParams as bytemuck::Zeroable>::zeroed())?;
        let partials = ctx.storage("fovea band partials", (3 * groups * 8) as u64)?;
        let theta = ctx.storage("fovea band phase", 16)?;
        let band_sum = ctx.kernel(&shaders::FOVEA, "band_sum")?;
        let band_phase = ctx.kernel(&shaders::FOVEA, "band_phase")?;
        let compose = ctx.kernel(&shaders::FOVEA, "compose")?;
        let binds = [
            ctx.bind_at(
                &band_sum,
                &[(0, &params), (1, tile), (2, image), (3, &partials)],
            ),
            ctx.bind_at(&band_phase, &[(0, &params), (3, &partials), (4, &theta)]),
            ctx.bind_at(
                &compose,
                &[(0, &params), (1, tile), (2, image), (4, &theta), (5, heads)],
            ),
        ];
        Ok(Self {
            shape,
            height,
            width,
            groups,
            params,
            theta,
            band_sum,
            band_phase,
            compose,
            binds,
        })
    }

    /// Writes the gaze's numbers of the next frame: the gaze `(x, y)` (pixels), its normalised depth, the
    /// tile's origin `(y, x)`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a tile origin that leaves the frame or a non-finite gaze.
    pub(crate) fn set_gaze(
        &self,
        ctx: &GpuContext,
        gaze: (f64, f64),
        gaze_depth: f32,
        (oy, ox): (usize, usize),
    ) -> Result<()> {
        let (th, tw) = self.shape.tile;
        if oy + th > self.height || ox + tw > self.width {
            return Err(invalid(
                "gaze",
                format!("the tile at ({oy}, {ox}) leaves the frame"),
            ));
        }
        if !(gaze.0.is_finite() && gaze.1.is_finite() && gaze_depth.is_finite()) {
            return Err(invalid("gaze", "is not finite"));
        }
        let s = &self.shape;
        // `h = |d − d_g|·s − 1/2`: the CPU's half-width of the blur's disc radius `blur_px·|d − d_g|`.
        let scale = s
            .blur_px
            .map(|b| (b * std::f64::consts::PI.sqrt() / 2.0) as f32);
        let (gx, gy) = (gaze.0.floor(), gaze.1.floor());
        let params = FoveaParams {
            h: self.height as u32,
            w: self.width as u32,
            th: th as u32,
            tw: tw as u32,
            oy: oy as u32,
            ox: ox as u32,
            groups: self.groups as u32,
            max_hw: s.max_half_width as f32,
            gx: gx as f32,
            gy: gy as f32,
            gx_frac: (gaze.0 - gx) as f32,
            gy_frac: (gaze.1 - gy) as f32,
            r_in: s.radius_px as f32,
            band: s.band_px as f32,
            gaze_depth,
            scale_r: scale[0],
            scale_g: scale[1],
            scale_b: scale[2],
            _pad: [0; 2],
        };
        ctx.write(&self.params, 0, bytemuck::bytes_of(&params));
        Ok(())
    }

    /// Records the band's phase and the composed heads.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        self.band_sum
            .dispatch(&mut pass, &self.binds[0], [self.groups as u32, 3, 1]);
        self.band_phase
            .dispatch(&mut pass, &self.binds[1], [1, 1, 1]);
        self.compose.dispatch(
            &mut pass,
            &self.binds[2],
            grid_1d(3 * self.height * self.width),
        );
    }

    /// The band's phase per colour (radians, f32 R, G, B and one unused) after a frame.
    pub(crate) fn theta_buffer(&self) -> &wgpu::Buffer {
        &self.theta
    }
}

/// The foveated frame's stages before the heads: the tile's CNN and [`GpuCompose`], with their buffers.
#[derive(Debug)]
pub(crate) struct GpuFovea {
    in_channels: usize,
    tile_input: wgpu::Buffer,
    image: wgpu::Buffer,
    cnn: GpuCnn,
    compose: GpuCompose,
    staging_theta: wgpu::Buffer,
}

impl GpuFovea {
    /// The tile's hologram CNN `hologram` (activations in `storage`) at `shape.tile`, and the compose kernels
    /// writing the heads `heads` (f32 `[6, H, W]`) of `height × width` frames.
    ///
    /// Errors: as [`GpuCnn::new`] and [`GpuCompose::new`].
    pub(crate) fn new(
        ctx: &GpuContext,
        hologram: &CnnWeights,
        shape: GpuFoveaShape,
        (height, width): (usize, usize),
        heads: &wgpu::Buffer,
        storage: GpuStorage,
    ) -> Result<Self> {
        let (th, tw) = shape.tile;
        let m = th * tw;
        let n = height * width;
        let in_channels = hologram.in_channels;
        let tile_input = ctx.storage("fovea tile input", (in_channels * m * 4) as u64)?;
        let tile_heads = ctx.storage("fovea tile heads", (6 * m * 4) as u64)?;
        let image = ctx.storage("fovea image", (4 * n * 4) as u64)?;
        let cnn = GpuCnn::new(ctx, hologram, th, tw, &tile_input, &tile_heads, storage)?;
        let compose = GpuCompose::new(ctx, shape, (height, width), &tile_heads, &image, heads)?;
        let read = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        let staging_theta = ctx.buffer("fovea band phase read-back", 16, read)?;
        Ok(Self {
            in_channels,
            tile_input,
            image,
            cnn,
            compose,
            staging_theta,
        })
    }

    /// Uploads one frame's inputs (the tile's CNN input, the image, the gaze).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for planes of another size; as [`GpuCompose::set_gaze`].
    pub(crate) fn upload(&self, ctx: &GpuContext, frame: &GpuFoveaFrame<'_>) -> Result<()> {
        let (th, tw) = self.compose.shape.tile;
        let (m, n) = (th * tw, self.compose.height * self.compose.width);
        if frame.tile.len() != self.in_channels || frame.tile.iter().any(|p| p.len() != m) {
            return Err(HoloError::ShapeMismatch {
                what: "GPU tile CNN input planes vs the session's [C, T_h·T_w]".into(),
                expected: vec![self.in_channels, m],
                got: vec![frame.tile.len(), frame.tile.first().map_or(0, |p| p.len())],
            });
        }
        if frame.amplitude.iter().any(|p| p.len() != n) || frame.depth.len() != n {
            return Err(HoloError::ShapeMismatch {
                what: "foveated frame planes vs the session's [H·W]".into(),
                expected: vec![n],
                got: vec![frame.depth.len()],
            });
        }
        self.compose
            .set_gaze(ctx, frame.gaze, frame.gaze_depth, frame.origin)?;
        for (i, plane) in frame.tile.iter().enumerate() {
            ctx.write(
                &self.tile_input,
                (i * m * 4) as u64,
                bytemuck::cast_slice(plane),
            );
        }
        for (i, plane) in frame.amplitude.iter().chain([&frame.depth]).enumerate() {
            ctx.write(&self.image, (i * n * 4) as u64, bytemuck::cast_slice(plane));
        }
        Ok(())
    }

    /// Records the tile's CNN and the composition, and the copy of the band's phase to its read-back buffer.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        self.cnn.record(encoder);
        self.compose.record(encoder);
        encoder.copy_buffer_to_buffer(self.compose.theta_buffer(), 0, &self.staging_theta, 0, 16);
    }

    /// The band's phase per colour (radians) of the last frame (after its submission was waited for).
    ///
    /// Errors: [`HoloError::Gpu`].
    pub(crate) fn read_theta(&self, ctx: &GpuContext) -> Result<[f32; 3]> {
        let mut bytes = [0u8; 16];
        ctx.read_staging(&self.staging_theta, &mut bytes)?;
        let v: [f32; 4] = bytemuck::cast(bytes);
        Ok([v[0], v[1], v[2]])
    }
}

/// The largest box half-width of the CPU periphery's blur for a largest disc radius `max_blur_px` on
/// `height × width` frames (`foveation::Periphery::new`: its tables' reach less one).
pub(crate) fn max_half_width(max_blur_px: f64, height: usize, width: usize) -> f64 {
    let reach =
        (crate::foveation::half_width(max_blur_px).floor() as usize + 1).min(height.max(width));
    reach.saturating_sub(1) as f64
}

/// The uniform structs of this module beside their WGSL twins (checked in `shader_tests`).
#[cfg(test)]
pub(super) fn uniform_layouts() -> Vec<super::shader_tests::UniformLayout> {
    use super::shader_tests::uniform_layout;
    vec![uniform_layout!(
        &super::shaders::FOVEA,
        "Fovea",
        FoveaParams {
            h,
            w,
            th,
            tw,
            oy,
            ox,
            groups,
            max_hw,
            gx,
            gy,
            gx_frac,
            gy_frac,
            r_in,
            band,
            gaze_depth,
            scale_r,
            scale_g,
            scale_b
        }
    )]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::foveation::{ColourInputs, FrameInputs, Gaze, Periphery, TileGeometry};
    use crate::gpu::test_support::{context as test_context, uniform as lcg};
    use num_complex::Complex64;
    use std::f64::consts::TAU;

    fn phasor(a: f32, p: f32) -> Complex64 {
        Complex64::from_polar(f64::from(a), (f64::from(p) - 0.5) * TAU)
    }

    /// The WGSL composition against the CPU's [`Periphery::compose`] on random heads, images and depths
    /// (depths beyond `[0, 1]` included: the blur's clamp), for a gaze inside the frame, one at a corner (the
    /// tile clipped) and one on an edge: the fovea bit for bit, the band's phase, and the field elsewhere.
    #[test]
    fn the_wgsl_composition_matches_the_cpu_periphery() {
        let Some(ctx) = test_context() else { return };
        let (h, w) = (70, 90);
        let n = h * w;
        let (radius, band) = (12.0, 6.0);
        let geometry = TileGeometry::new(radius, band, 3, h, w);
        let blur_px = [3.0, 4.5, 9.0];
        let max_blur = 9.0;
        let periphery = Periphery::new(geometry, max_blur, 2, tensorholo_kernels::Isa::detect());
        let shape = GpuFoveaShape {
            tile: geometry.tile,
            radius_px: radius,
            band_px: band,
            blur_px,
            max_half_width: max_half_width(max_blur, h, w),
        };
        let (th, tw) = geometry.tile;
        let m = th * tw;
        let mut r = lcg(7);
        let amplitude: Vec<f32> = (0..3 * n).map(|_| r()).collect();
        let depth: Vec<f32> = (0..n).map(|_| 1.2 * r() - 0.1).collect();
        let tile: Vec<f32> = (0..6 * m)
            .map(|e| if e < 3 * m { 1.4 * r() } else { r() })
            .collect();
        let mut image = amplitude.clone();
        image.extend_from_slice(&depth);
        let tile_buf = ctx.storage_with("tile", &tile).unwrap();
        let image_buf = ctx.storage_with("image", &image).unwrap();
        let heads_buf = ctx.storage("heads", (6 * n * 4) as u64).unwrap();
        let compose =
            GpuCompose::new(&ctx, shape, (h, w), &tile_buf, &image_buf, &heads_buf).unwrap();
        for (gx, gy, d_g) in [(40.3, 33.7, 0.4f32), (0.2, 68.6, 0.9), (89.0, 20.5, 0.0)] {
            let gaze = Gaze {
                x: gx,
                y: gy,
                depth_m: None,
            };
            let origin = geometry.origin(&gaze);
            let before = ctx.resource_counts();
            compose.set_gaze(&ctx, (gx, gy), d_g, origin).unwrap();
            let mut enc = ctx.encoder("test");
            compose.record(&mut enc);
            ctx.submit_and_wait(enc).unwrap();
            assert_eq!(ctx.resource_counts(), before, "a frame created GPU objects");
            let got: Vec<f32> = ctx.read_buffer(&heads_buf, 6 * n).unwrap();
            let theta: Vec<f32> = ctx.read_buffer(compose.theta_buffer(), 4).unwrap();
            let colours = [0, 1, 2].map(|c| ColourInputs {
                amplitude: &amplitude[c * n..(c + 1) * n],
                scale: None,
                tile_heads: (&tile[c * m..(c + 1) * m], &tile[(3 + c) * m..(4 + c) * m]),
                blur_px: blur_px[c],
            });
            let frame = FrameInputs {
                depth: &depth,
                gaze: (gx, gy),
                gaze_depth: d_g,
                origin,
            };
            let mut want = vec![0.0f32; 6 * n];
            let [o0, o1, o2, o3, o4, o5] = {
                let (a, rest) = want.split_at_mut(n);
                let (b, rest) = rest.split_at_mut(n);
                let (c, rest) = rest.split_at_mut(n);
                let (d, rest) = rest.split_at_mut(n);
                let (e, f) = rest.split_at_mut(n);
                [a, b, c, d, e, f]
            };
            let phases = periphery
                .compose(frame, colours, [o0, o1, o2, o3, o4, o5])
                .unwrap();
            let (mut fovea, mut band_max, mut out_max, mut counts) = (0, 0.0f64, 0.0f64, [0; 3]);
            for c in 0..3 {
                let dt = (f64::from(theta[c]) - f64::from(phases[c])).abs();
                assert!(
                    dt < 1e-4,
                    "gaze ({gx}, {gy}) colour {c}: θ {} vs {}",
                    theta[c],
                    phases[c]
                );
                for i in 0..n {
                    let (y, x) = (i / w, i % w);
                    let rr = (x as f64 - gx).hypot(y as f64 - gy);
                    let (ga, gp) = (got[c * n + i], got[(3 + c) * n + i]);
                    let (wa, wp) = (want[c * n + i], want[(3 + c) * n + i]);
                    if rr <= radius - 1e-3 {
                        assert_eq!((ga.to_bits(), gp.to_bits()), (wa.to_bits(), wp.to_bits()));
                        fovea += 1;
                        continue;
                    }
                    let d = (phasor(ga, gp) - phasor(wa, wp)).norm();
                    if rr < radius + band {
                        band_max = band_max.max(d);
                        counts[1] += 1;
                    } else {
                        out_max = out_max.max(d);
                        counts[2] += 1;
                    }
                }
            }
            println!(
                "gaze ({gx}, {gy}), tile at {origin:?}: fovea {fovea} pixels bit for bit, max |ΔU| band \
                 {band_max:.1e} ({} px), periphery {out_max:.1e} ({} px)",
                counts[1], counts[2]
            );
            assert!(fovea > 0 && counts[1] > 0 && counts[2] > 0);
            assert!(band_max < 1e-4, "band {band_max}");
            assert!(out_max < 1e-4, "periphery {out_max}");
        }
    }
}
