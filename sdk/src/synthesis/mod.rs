//! Reference hologram synthesis: the silhouette-mask layer-based method (SM-LBM, paper Eq. 1–4) on RGB-D
//! images and layered depth images, producing the midpoint hologram that the CNNs learn.

mod sm_lbm;

pub use sm_lbm::{SceneLayer, SmLbm};
