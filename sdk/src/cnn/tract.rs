//! tract's engine: [`ModelPlan`] (an optimised tract plan at one resolution, cached in its
//! [`crate::model::HologramModel`]) as a [`CnnPlan`].

use ndarray::{Array3, ArrayView3};

use super::CnnPlan;
use crate::error::Result;
use crate::model::ModelPlan;

impl CnnPlan for ModelPlan {
    fn input_dim(&self) -> (usize, usize, usize) {
        ModelPlan::input_dim(self)
    }

    fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
        ModelPlan::run_outputs(self, input)
    }

    fn spawn(&self) -> Box<dyn CnnPlan> {
        // A tract plan is an `Arc` of the optimised graph: a clone shares it, and each run makes its state.
        Box::new(self.clone())
    }
}
