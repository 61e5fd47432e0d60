//! What the frame looks at: the camera's rays, the pixels no 1-cell can
//! reach (culled before any ray), and the default frame.
//!
//! ```text
//! camera.rs   a ray per pixel (orthographic or perspective), orbits
//! cull.rs     pixels no brick with 1-cells projects onto: no ray
//! framing.rs  the default frame: the box of the scene's 1-cells
//! ```

pub mod camera;
pub(crate) mod cull;
pub mod framing;
