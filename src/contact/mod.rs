//! Contact physics: the contact law and its elastic potential, its history store, and wall
//! contacts.

mod facet_grid;
pub mod friction;
pub mod history;
pub mod inputs;
pub mod law;
pub mod potential;
pub mod restitution;
pub mod trajectory;
pub mod wall;

pub use history::{ContactHistory, ContactKey, ContactState, WALL_BIT};
pub use law::{ContactForces, ContactKinematics, ContactParameters, contact_forces, mass_share};
pub use restitution::hunt_crossley_alpha;
pub use trajectory::FaceWindow;
pub use wall::WallMesh;
