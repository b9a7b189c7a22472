//! polydem: discrete element method for convex polyhedral particles.
//!
//! The crate is laid out by concept (see `DESIGN.md` §2): [`shape`] builds particle templates,
//! [`geometry`] holds the exact contact-geometry queries (GJK, overlap volume by dual-space
//! Quickhull, wall clipping), and [`probe`] exposes those queries to users and tests.

pub mod accuracy;
pub mod backend;
pub mod contact;
pub mod domain;
pub mod geometry;
pub mod integrate;
pub mod interrupt;
pub mod io;
pub mod neighbor;
pub mod pipeline;
pub mod probe;
pub mod rng;
pub mod run;
pub mod scene;
pub mod shape;
pub mod stability;
pub mod state;
pub mod tuning;
