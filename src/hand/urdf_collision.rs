//! A URDF link's `<collision>` elements as the hand's colliders (part of the URDF loader,
//! `urdf.rs`): spheres, boxes, cylinders and capsules as written, meshes (STL, OBJ; `package://`,
//! `file://` or relative paths) fitted with the tightest primitive where `hand.mesh_approx` opts
//! in, each fit reported.

use super::urdf::{DPose, Loader, R, fmt3, fnum, urdf_pose};
use super::*;
use crate::mesh::fit::{FittedShape, PrimitiveKind, axis_aligned_with_hull, fit_tightest_with_hull};
use crate::mesh::hull::convex_hull;
use crate::mesh::read::{parse_obj, parse_stl};

impl Loader<'_> {
    /// Collision element `ci` of link `l` (link index `link`, at `lpose`) as a collider: a sphere,
    /// box or capsule as written (a cylinder becomes the capsule on its segment), or a mesh fitted
    /// with a primitive where `hand.mesh_approx` allows.
    pub(super) fn collider(&self, l: &urdf_rs::Link, ci: usize, c: &urdf_rs::Collision, link: usize, lpose: DPose) -> R<Collider> {
        let f = &self.file;
        let name = &l.name;
        let pose = lpose.mul(&urdf_pose(&c.origin));
        let what = match &c.name {
            Some(n) => format!("collision '{n}'"),
            None => format!("collision {ci}"),
        };
        let radius_ok = |r: f64| r.is_finite() && r > 0.0 && r <= MAX_LENGTH_M;
        let size_ok = |s: f64| s.is_finite() && (0.0..=MAX_LENGTH_M).contains(&s);
        let (pose, shape) = match &c.geometry {
            urdf_rs::Geometry::Sphere { radius } => {
                if !radius_ok(*radius) {
                    return Err(format!(
                        "link '{name}' in {f}: {what} sphere radius {}; expected a positive finite radius <= {MAX_LENGTH_M} (m)",
                        fnum(*radius)
                    ));
                }
                (pose, ColliderShape::Sphere { radius: *radius as f32 })
            }
            urdf_rs::Geometry::Box { size } => {
                if !size.0.iter().all(|&s| size_ok(s)) {
                    return Err(format!(
                        "link '{name}' in {f}: {what} box size {}; expected finite sizes in [0, {MAX_LENGTH_M}] (m)",
                        fmt3(&size.0)
                    ));
                }
                let half = DVec3::from_array(size.0) * 0.5;
                (pose, ColliderShape::Box { half_extents: half.as_vec3() })
            }
            urdf_rs::Geometry::Cylinder { radius, length } | urdf_rs::Geometry::Capsule { radius, length } => {
                let kind = if matches!(c.geometry, urdf_rs::Geometry::Cylinder { .. }) { "cylinder" } else { "capsule" };
                if !radius_ok(*radius) || !size_ok(*length) {
                    return Err(format!(
                        "link '{name}' in {f}: {what} {kind} radius {} length {}; expected a positive finite radius and a finite length >= 0, both <= {MAX_LENGTH_M} (m)",
                        fnum(*radius),
                        fnum(*length)
                    ));
                }
                (pose, ColliderShape::Capsule { radius: *radius as f32, half_length: (*length * 0.5) as f32 })
            }
            urdf_rs::Geometry::Mesh { filename, scale } => match self.opts.mesh_approx {
                MeshApprox::Error => {
                    return Err(format!(
                        "link '{name}' in {f} has a <mesh> {what} ('{filename}'); expected sphere, box, cylinder or capsule collision geometry (or opt in to a fitted primitive with hand.mesh_approx = \"capsule\" or \"box\")"
                    ));
                }
                approx => self.mesh_collider(name, filename, scale.as_ref(), approx, pose)?,
            },
        };
        Ok(Collider { link, pose: pose.to_pose(), shape })
    }

    /// Candidate paths of a mesh file name, in lookup order.
    fn mesh_candidates(&self, filename: &str) -> Vec<PathBuf> {
        let parent = self.source.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let dir = std::fs::canonicalize(parent).unwrap_or_else(|_| parent.to_path_buf());
        if let Some(rest) = filename.strip_prefix("package://") {
            let (pkg, rel) = rest.split_once('/').unwrap_or(("", rest));
            let mut v = Vec::new();
            for a in dir.ancestors() {
                v.push(a.join(rel));
                if !pkg.is_empty() {
                    v.push(a.join(pkg).join(rel));
                }
            }
            v
        } else {
            let p = Path::new(filename.strip_prefix("file://").unwrap_or(filename));
            vec![if p.is_absolute() { p.to_path_buf() } else { dir.join(p) }]
        }
    }

    fn mesh_collider(
        &self,
        link: &str,
        filename: &str,
        scale: Option<&urdf_rs::Vec3>,
        approx: MeshApprox,
        pose: DPose,
    ) -> R<(DPose, ColliderShape)> {
        let f = &self.file;
        let ext = Path::new(filename).extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        if ext != "stl" && ext != "obj" {
            return Err(format!(
                "link '{link}' in {f}: mesh '{filename}' has unsupported format '.{ext}'; expected a .stl (binary or ASCII) or .obj mesh for mesh_approx"
            ));
        }
        let scale = scale.map_or(DVec3::ONE, |s| DVec3::from_array(s.0));
        if !scale.is_finite() || scale.abs().max_element() > MAX_MESH_SCALE {
            return Err(format!(
                "link '{link}' in {f}: mesh '{filename}' has scale {}; expected finite numbers within ±{MAX_MESH_SCALE}",
                fmt3(&scale.to_array())
            ));
        }
        let candidates = self.mesh_candidates(filename);
        let Some(path) = candidates.iter().find(|p| p.is_file()) else {
            return Err(format!(
                "link '{link}' in {f}: mesh file '{filename}' not found (looked for {}{}); expected a path relative to the URDF directory, package://pkg/path or file:///absolute/path",
                candidates[0].display(),
                if candidates.len() > 1 { " and in parent directories" } else { "" }
            ));
        };
        let bytes = std::fs::read(path)
            .map_err(|e| format!("link '{link}' in {f}: cannot read mesh {}: {e}", path.display()))?;
        let verts = if ext == "stl" { parse_stl(&bytes) } else { parse_obj(&bytes) }
            .map_err(|e| format!("link '{link}' in {f}: cannot read mesh {}: {e}", path.display()))?;
        if verts.is_empty() {
            return Err(format!("link '{link}' in {f}: mesh {} has no vertices; expected a non-empty mesh", path.display()));
        }
        let scaled: Vec<DVec3> = verts.iter().map(|v| *v * scale).collect();
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for v in &scaled {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
        let centre = (lo + hi) * 0.5;
        let half = (hi - lo) * 0.5;
        if centre.abs().max_element() > MAX_LENGTH_M || half.max_element() > MAX_LENGTH_M {
            return Err(format!(
                "link '{link}' in {f}: mesh {} spans {} .. {} (scaled, m); expected a mesh within ±{MAX_LENGTH_M} m of its frame (in metres: set <mesh scale> for a mesh in millimetres)",
                path.display(),
                lo,
                hi
            ));
        }
        let kinds: &[PrimitiveKind] = match approx {
            MeshApprox::Box => &[PrimitiveKind::Box],
            _ => &[PrimitiveKind::Capsule, PrimitiveKind::Sphere],
        };
        // one hull serves the fit and the axis-aligned primitive it is compared with
        let mesh_err = |e: String| format!("link '{link}' in {f}: mesh {}: {e}", path.display());
        let hull = convex_hull(&scaled).map_err(mesh_err)?;
        let fit = fit_tightest_with_hull(&scaled, &hull, kinds).map_err(mesh_err)?;
        let aligned = axis_aligned_with_hull(&scaled, &hull, fit.kind());
        let shape = match fit.shape {
            FittedShape::Sphere { radius } => ColliderShape::Sphere { radius: radius as f32 },
            FittedShape::Capsule { radius, half_length } => ColliderShape::Capsule { radius: radius as f32, half_length: half_length as f32 },
            FittedShape::Box { half_extents } => ColliderShape::Box { half_extents: half_extents.as_vec3() },
            // not among the kinds asked for above; the capsule on the same segment contains it
            FittedShape::Cylinder { radius, half_length } => ColliderShape::Capsule { radius: radius as f32, half_length: half_length as f32 },
        };
        self.mesh_fits.borrow_mut().push(MeshFitReport {
            link: link.to_string(),
            mesh: path.clone(),
            shape,
            hull_volume: fit.hull_volume as f32,
            volume_ratio: fit.volume_ratio() as f32,
            aligned_volume_ratio: aligned.volume_ratio() as f32,
            max_gap: fit.max_gap as f32,
        });
        Ok((pose.mul(&DPose { pos: fit.centre, rot: fit.rot }), shape))
    }
}
