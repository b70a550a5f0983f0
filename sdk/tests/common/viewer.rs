//! A simulated viewer behind the paper's eyepiece, with an optional thin lens at its exit pupil, written from
//! the physical formula (not with the SDK's Zernike code): the shared model of the aberration tests
//! (`docs/ABERRATION.md`, "Viewer model").
//!
//! The eyepiece (focal length [`EYEPIECE_M`]) puts the Fourier plane of hologram space at its exit pupil, so a
//! spatial frequency `f` of the hologram crosses the pupil at `r = λ·f_e·f`, and a thin lens there adds the
//! pupil phase `−π·r²·P/λ` for its power `P` along `r`. The pupil passes `|f| ≤ f_N = 1/(2p)`. What the viewer
//! sees focused at normalised depth `d` is `|ASM(F⁻¹{F(H)·P_lens·circ}, z(d))|` for the midpoint hologram `H`.

use std::f64::consts::PI;

use ndarray::{Array2, Array3, Axis};
use num_complex::Complex32;
use tensorholo::optics::fft::signed_index;
use tensorholo::optics::{Carrier, OpticalSetup, PropagationOptions};

/// Focal length of the paper's eyepiece (metres).
pub const EYEPIECE_M: f64 = 21e-3;

/// A thin spherocylindrical lens at the viewer's pupil: `sphere` dioptres in every meridian plus `cylinder`
/// dioptres across the axis, whose direction is `axis_deg` from the hologram's `+x` toward its `+y` (rows).
#[derive(Debug, Clone, Copy)]
pub struct Lens {
    pub sphere: f64,
    pub cylinder: f64,
    pub axis_deg: f64,
}

impl Lens {
    /// A cylindrical lens of focal length `focal_m` whose axis is `axis_deg` (90: vertical, power along x).
    pub fn cylinder(focal_m: f64, axis_deg: f64) -> Self {
        Self {
            sphere: 0.0,
            cylinder: 1.0 / focal_m,
            axis_deg,
        }
    }

    /// The pupil phase (radians) at hologram frequency `(fx, fy)` (cycles per metre) for wavelength `lambda`.
    pub fn phase(&self, fx: f64, fy: f64, lambda: f64) -> f64 {
        let a = self.axis_deg.to_radians();
        // Across the axis: n = (−sin a, cos a).
        let across = -fx * a.sin() + fy * a.cos();
        -PI * lambda
            * EYEPIECE_M
            * EYEPIECE_M
            * (self.sphere * (fx * fx + fy * fy) + self.cylinder * across * across)
    }
}

/// `exp(i·phase)` of `lens` (or 1 without one) times the eyepiece pupil `|f| ≤ 1/(2p)`, in the spectrum layout
/// of an unpadded `[h, w]` plan: index `kx·h + ky`, FFT order.
pub fn viewer_pupil(
    h: usize,
    w: usize,
    pitch: f64,
    lambda: f64,
    lens: Option<Lens>,
) -> Vec<Complex32> {
    let f_n = 1.0 / (2.0 * pitch);
    let mut out = Vec::with_capacity(h * w);
    for kx in 0..w {
        let fx = signed_index(kx, w) as f64 / (w as f64 * pitch);
        for ky in 0..h {
            let fy = signed_index(ky, h) as f64 / (h as f64 * pitch);
            if fx * fx + fy * fy > f_n * f_n {
                out.push(Complex32::new(0.0, 0.0));
                continue;
            }
            let phase = lens.map_or(0.0, |l| l.phase(fx, fy, lambda));
            let (s, c) = phase.sin_cos();
            out.push(Complex32::new(c as f32, s as f32));
        }
    }
    out
}

/// What the viewer sees focused at normalised depth `d` through `lens`: `|ASM(F⁻¹{F(H)·P·circ}, z(d))|` per
/// colour `[3, h, w]`, for the midpoint hologram `hologram` `[3, h, w]`.
pub fn seen(
    hologram: &Array3<Complex32>,
    setup: &OpticalSetup,
    d: f64,
    lens: Option<Lens>,
) -> Array3<f32> {
    let (_, h, w) = hologram.dim();
    let props = setup
        .propagators(h, w, PropagationOptions::default())
        .unwrap();
    let mut out = Array3::<f32>::zeros((3, h, w));
    for (c, prop) in props.iter().enumerate() {
        let plan = prop.plan();
        let mut scratch = plan.scratch();
        let mut spectrum = vec![Complex32::default(); plan.spectrum_len()];
        let lane = hologram.index_axis(Axis(0), c).to_owned();
        plan.forward(lane.as_slice().unwrap(), &mut spectrum, &mut scratch)
            .unwrap();
        let mut tf = prop
            .transfer_function(setup.depth_to_z(d), Carrier::Remove)
            .unwrap();
        tf.multiply(&viewer_pupil(
            h,
            w,
            setup.pixel_pitch_m,
            prop.wavelength_m(),
            lens,
        ))
        .unwrap();
        let mut field = vec![Complex32::default(); h * w];
        plan.inverse(&spectrum, tf.values(), &mut field, &mut scratch)
            .unwrap();
        for (o, v) in out.index_axis_mut(Axis(0), c).iter_mut().zip(&field) {
            *o = v.norm();
        }
    }
    out
}

/// PSNR (data range 1) of `test` against `reference` over the pixels where `region` holds (every pixel with
/// `None`), all colours.
pub fn psnr_in(reference: &Array3<f32>, test: &Array3<f32>, region: Option<&Array2<bool>>) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for c in 0..3 {
        let r = reference.index_axis(Axis(0), c);
        let t = test.index_axis(Axis(0), c);
        for ((idx, r), t) in r.indexed_iter().zip(t.iter()) {
            if region.is_none_or(|m| m[idx]) {
                sum += ((r - t) as f64).powi(2);
                n += 1;
            }
        }
    }
    10.0 * (n as f64 / sum).log10()
}
