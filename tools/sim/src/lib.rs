//! topoloc-sim: procedural indoor worlds for measuring topological localization.
//!
//! Deterministic from a seed: a world generator (rooms, corridors, doors, floors, textures,
//! landmarks, furniture) as a 3D voxel grid, a CPU ray-casting renderer with lighting conditions,
//! trajectories with ground truth and drifting odometry, and a dataset writer/reader that
//! `topoloc eval` understands.
//!
//! Frames and conventions (shared by every module): world metres, z up. A camera or body pose is
//! `world_T_body` ([`camera::Pose`]): the body looks along its x axis, y to its left, z up; yaw
//! turns about world z. Image pixels follow [`camera::Intrinsics`] (pinhole, optical axis = body
//! x, image right = body -y, image down = body -z).

pub mod camera;
pub mod capture;
pub mod dataset;
pub mod ground_truth;
pub mod odometry;
pub mod render;
pub mod rng;
pub mod scenario;
pub mod style;
pub mod texture;
pub mod trajectory;
pub mod world;
