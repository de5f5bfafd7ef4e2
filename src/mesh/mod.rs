//! Meshes as collision geometry: reading them, their convex hull, and tight primitive fits.
//!
//! General (not hand-specific): the URDF loader fits a primitive to each `<mesh>` collision
//! (`mesh_approx`), and objects made from meshes can do the same.
//!
//! - [`read`]: the vertices of STL (binary and ASCII) and OBJ files.
//! - [`mass`]: volume, centre of mass and inertia of the solid a closed triangle mesh
//!   ([`read::TriangleMesh`], from `read::parse_stl_mesh` or `read::parse_obj_pieces`) encloses,
//!   whether a mesh is closed, and the union of pieces.
//! - [`hull`]: the 3D convex hull of a point cloud (quickhull with conflict lists on exact
//!   orientation predicates), its volume, area, principal axes of its surface and the distance
//!   from a point to it.
//! - [`fit`]: the smallest sphere, capsule or oriented box that contains every vertex, searched
//!   over the hull's principal frame, the mesh's own axes and rotations between them; with how
//!   much bigger it is than the mesh (volume against the hull's, and the largest gap between the
//!   primitive's surface and the hull).
//!
//! Units are those of the vertices (metres in dextrain); nothing here scales or moves a mesh.

pub mod fit;
pub mod hull;
pub mod mass;
pub mod read;
