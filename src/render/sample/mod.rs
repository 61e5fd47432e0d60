//! What a ray does at a 1-cell, shared by every integrator and
//! traversal: find the hit inside the cell, shade it, look values up.
//!
//! ```text
//! hit.rs      the first crossing of the iso value inside a cell
//!             (paper section 5.3)
//! shade.rs    the cell's trilinear interpolant along a ray, and Phong
//! normals.rs  shading normals: the cell's own or smooth (central
//!             differences across bricks, through the cache)
//! lut.rs      transfer-function lookup tables (opacity, colour)
//! pretable.rs the segment integrator's extinction integral table
//! ```

pub mod hit;
pub mod lut;
pub mod pretable;
pub mod normals;
pub mod shade;
