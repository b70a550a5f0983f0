//! Reference hologram synthesis: the silhouette-mask layer-based method (SM-LBM, paper Eq. 1–4) on RGB-D
//! images and layered depth images, producing the midpoint hologram that the CNNs learn, and its
//! aberration-corrected variant (Eq. 5; the Zernike terms and the pupil kernel of Eq. 14–19 are
//! [`crate::optics::zernike`], the calibrated profile [`crate::display::AberrationProfile`]; `docs/ABERRATION.md`).

mod aberration;
mod sm_lbm;

pub use aberration::{AberrationCorrectedSmLbm, AberrationCorrection};
pub use sm_lbm::{SceneLayer, SmLbm};

use crate::scene::{LayeredDepthImage, LdiLayer, RgbdFrame};

impl<'a> From<&'a RgbdFrame> for SceneLayer<'a> {
    /// An RGB-D frame is one layer in which every pixel holds a point.
    fn from(frame: &'a RgbdFrame) -> Self {
        SceneLayer {
            amplitude: frame.amplitude.view(),
            depth: frame.depth.view(),
            valid: None,
        }
    }
}

impl<'a> From<&'a LdiLayer> for SceneLayer<'a> {
    /// One LDI layer with its validity mask.
    fn from(layer: &'a LdiLayer) -> Self {
        SceneLayer {
            amplitude: layer.amplitude.view(),
            depth: layer.depth.view(),
            valid: Some(layer.valid.view()),
        }
    }
}

/// The layers of a layered depth image (front to back) as [`SceneLayer`]s for [`SmLbm::synthesize`].
pub fn ldi_layers(ldi: &LayeredDepthImage) -> Vec<SceneLayer<'_>> {
    ldi.layers().iter().map(SceneLayer::from).collect()
}
