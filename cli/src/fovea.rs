//! The foveation flags `holo render` and `holo video` share ([`FoveaArgs`]: the gaze, its depth, the fovea's
//! size) and how they become the SDK's [`FoveationOptions`] and [`Gaze`] (docs/FOVEATION.md).

use anyhow::{bail, Context, Result};
use clap::Args;
use tensorholo::display::DEFAULT_EYEPIECE_FOCAL_M;
use tensorholo::foveation::{FoveaRadius, FoveationOptions, Gaze, DEFAULT_BAND_PX};

/// Foveated frames: the hologram CNN only where the viewer looks (docs/FOVEATION.md).
#[derive(Debug, Args)]
pub struct FoveaArgs {
    /// Foveate every frame on this gaze point X,Y: output pixels after --size, (0, 0) the top-left pixel's
    /// centre, x right, y down. The hologram CNN runs on a tile around it (the fovea, a blend band and the
    /// CNN's receptive radius); elsewhere the frame is a 2D hologram with synthetic blur, in focus at the
    /// gaze's depth. Default fovea: 5° behind the paper's 21 mm eyepiece.
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true)]
    pub gaze: Option<String>,
    /// The depth the viewer focuses at, metres from the midpoint plane in hologram space (positive towards
    /// the viewer, as the focal planes: the volume's near end at +volume/2). Default: the scene's depth at the
    /// gaze point (the median of a 17×17 window).
    #[arg(
        long,
        value_name = "METRES",
        allow_hyphen_values = true,
        requires = "gaze"
    )]
    pub gaze_depth: Option<f64>,
    /// The fovea's radius in degrees of visual angle behind the eyepiece (--eyepiece-mm, default 21 mm):
    /// R_px = f·tan(R)/pitch. Default 5.
    #[arg(
        long,
        value_name = "DEGREES",
        requires = "gaze",
        conflicts_with = "fovea_px"
    )]
    pub fovea_deg: Option<f64>,
    /// The fovea's radius in SLM pixels (instead of --fovea-deg).
    #[arg(long, value_name = "PIXELS", requires = "gaze")]
    pub fovea_px: Option<f64>,
    /// Width in pixels of the blend band outside the fovea (from R to R + band): the CNN's field fades
    /// linearly into the periphery's there.
    #[arg(long, value_name = "PIXELS", requires = "gaze", default_value_t = DEFAULT_BAND_PX)]
    pub fovea_band_px: f64,
}

impl FoveaArgs {
    /// The foveation options of the flags (`None` without --gaze); `eyepiece_mm` is --eyepiece-mm.
    /// Errors: name the flag of a value the SDK refuses (a negative or non-finite radius, a band under 1).
    pub fn options(&self, eyepiece_mm: Option<f64>) -> Result<Option<FoveationOptions>> {
        if self.gaze.is_none() {
            return Ok(None);
        }
        let radius = match (self.fovea_px, self.fovea_deg) {
            (Some(pixels), _) => FoveaRadius::Pixels { pixels },
            (None, degrees) => FoveaRadius::Degrees {
                degrees: degrees.unwrap_or(5.0),
                eyepiece_focal_m: eyepiece_mm.map_or(DEFAULT_EYEPIECE_FOCAL_M, |mm| mm * 1e-3),
            },
        };
        let options = FoveationOptions {
            radius,
            band_px: self.fovea_band_px,
            ..FoveationOptions::default()
        };
        // The SDK's checks, at the flags (the pitch only scales a valid radius).
        if let Err(e) = options.check() {
            let flag = match (&e, self.fovea_px.is_some()) {
                (
                    tensorholo::HoloError::InvalidParameter {
                        name: "band_px", ..
                    },
                    _,
                ) => "--fovea-band-px",
                (
                    tensorholo::HoloError::InvalidParameter {
                        name: "eyepiece_focal_m",
                        ..
                    },
                    _,
                ) => "--eyepiece-mm",
                (_, true) => "--fovea-px",
                (_, false) => "--fovea-deg",
            };
            return Err(anyhow::Error::new(e).context(flag));
        }
        Ok(Some(options))
    }

    /// The gaze of --gaze and --gaze-depth (`None` without --gaze). Errors: a value that is not `X,Y` with two
    /// finite numbers, a non-finite --gaze-depth (the frame's bounds are checked by the SDK, per frame).
    pub fn gaze(&self) -> Result<Option<Gaze>> {
        let Some(text) = &self.gaze else {
            return Ok(None);
        };
        let (x, y) = parse_point(text).with_context(|| format!("--gaze {text}"))?;
        if let Some(d) = self.gaze_depth {
            if !d.is_finite() {
                bail!("--gaze-depth {d}: must be a finite distance in metres");
            }
        }
        Ok(Some(Gaze {
            x,
            y,
            depth_m: self.gaze_depth,
        }))
    }
}

/// `X,Y` as two finite numbers. Errors: anything else, saying what is expected.
pub fn parse_point(text: &str) -> Result<(f64, f64)> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, y] = parts.as_slice() else {
        bail!("expected X,Y (two numbers, pixels), e.g. --gaze 960,540");
    };
    let number = |s: &str, what: &str| -> Result<f64> {
        let v: f64 = s
            .parse()
            .with_context(|| format!("{what} {s:?} is not a number"))?;
        if !v.is_finite() {
            bail!("{what} {s:?} is not finite");
        }
        Ok(v)
    };
    Ok((number(x, "X")?, number(y, "Y")?))
}
