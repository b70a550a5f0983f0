//! Shared by the GPU tests: the context they run on, or a skip (`tensorholo::gpu::test_context`).
#![allow(dead_code)]

pub use tensorholo::gpu::test_context as context;
