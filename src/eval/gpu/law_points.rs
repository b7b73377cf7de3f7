//! A law file's WGSL at arbitrary points (`shaders/law_file_points.wgsl`): its torque and
//! dT/dw in f32 on the GPU, for comparing with the f64 CPU twin.

use super::{GpuError, STORAGE_READ, STORAGE_WRITE};
use crate::laws::file::LawFile;

/// One point: the law's parameters (unused ones 0), bit speed (rad/s) and weight-on-bit ratio.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Point {
    pub p: [f32; 6],
    pub w: f32,
    pub r: f32,
}

/// The kernel's source: the shared laws, the law's functions and the entry point.
fn source(law: &LawFile) -> String {
    let name = &law.name;
    [
        crate::laws::LAWS_WGSL.to_string(),
        law.wgsl(),
        format!(
            "fn law_torque(p: array<f32, 6>, w: f32, r: f32) -> f32 {{ return file_torque_{name}(p, w, r); }}\n\
             fn law_slope(p: array<f32, 6>, w: f32, r: f32) -> f32 {{ return file_slope_{name}(p, w, r); }}"
        ),
        include_str!("../../../shaders/law_file_points.wgsl").to_string(),
    ]
    .join("\n")
}

/// (T, dT/dw) of `law` at every point, f32, on the GPU.
pub fn torques(law: &LawFile, points: &[Point]) -> Result<Vec<[f32; 2]>, GpuError> {
    let ctx = super::context()?;
    let bindings = [STORAGE_READ, STORAGE_WRITE];
    // The cache key holds the generated text, so that two laws of one name never share a kernel.
    let label = format!("law_file_points {}", law.wgsl());
    let kernel = ctx.kernel(&label, "main", || source(law), &bindings, &[])?;
    let mut results = Vec::with_capacity(points.len());
    // Chunks of 2¹⁸ points (8 MiB) stay inside every adapter's storage-binding limit.
    for chunk in points.chunks(1 << 18) {
        let raw = ctx.map_elements(
            "law_file_points",
            &kernel,
            bytemuck::cast_slice(chunk),
            chunk.len() as u32,
            8 * chunk.len() as u64,
        )?;
        results.extend(bytemuck::cast_slice::<u8, [f32; 2]>(&raw).iter().copied());
    }
    Ok(results)
}
