//! Which pixels an edge crosses: where a pixel's four corners do not all see one surface (a
//! silhouette, a crease, where two objects or materials meet, or the background behind). A
//! box filter's error is largest there: one or a few samples put the whole pixel on one side
//! of the edge, whatever share of it the other side covers, while inside a surface the
//! records and the shadow-ray pool already make few samples enough. Those pixels take
//! `--edge-samples` samples instead of `--spp` (`render_tile`).
//!
//! The corners are rays of their own, one per corner (a tile's pixels share theirs), no
//! shading and no randomness, so a pixel is an edge pixel or not whatever the tiles, threads
//! or ranks. Detail smaller than a pixel between its corners, and texture detail within one
//! surface, are left to `--spp`.

use crate::scene::view::Camera;
use crate::shading::{Integrator, Work};
use crate::tiles::Tile;
use crate::tracer::SurfaceHit;

/// The pixels of `tile` an edge crosses, row-major.
pub fn edge_pixels(integrator: &Integrator<'_>, camera: &Camera, tile: &Tile, work: &mut Work<'_>) -> Vec<bool> {
    let (width, height) = ((tile.x1 - tile.x0) as usize, (tile.y1 - tile.y0) as usize);
    let mut corners = Vec::with_capacity((width + 1) * (height + 1));
    for y in tile.y0..=tile.y1 {
        for x in tile.x0..=tile.x1 {
            let (origin, dir) = camera.ray(x as f32, y as f32);
            corners.push(integrator.eye_surface(origin, dir, work));
        }
    }
    let corner = |x: usize, y: usize| &corners[y * (width + 1) + x];
    let mut edges = Vec::with_capacity(width * height);
    for y in 0..height {
        for x in 0..width {
            let first = corner(x, y);
            let others = [corner(x + 1, y), corner(x, y + 1), corner(x + 1, y + 1)];
            edges.push(others.iter().any(|other| !one_surface(first, other)));
        }
    }
    edges
}

/// Whether two corners see one surface: both nothing, or the same object and material on one
/// plane.
fn one_surface(a: &Option<SurfaceHit>, b: &Option<SurfaceHit>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.object == b.object && a.material == b.material && a.on_plane_of(b),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn hit(position: Vec3, normal: Vec3, object: u32, material: u32) -> Option<SurfaceHit> {
        Some(SurfaceHit {
            position,
            distance: 1.0,
            geometric_normal: normal,
            normal,
            facing_normal: normal,
            uv: None,
            uv_per_length: 0.0,
            material,
            object,
            prim_id: 0,
        })
    }

    #[test]
    fn corners_see_one_surface_only_on_one_plane_of_one_object_and_material() {
        let floor = |x: f32, z: f32| hit(Vec3::new(x, 0.0, z), Vec3::Y, 3, 1);
        // Two points of one floor, near and far apart (another triangle of it, say).
        assert!(one_surface(&floor(0.0, 0.0), &floor(0.01, 0.0)));
        assert!(one_surface(&floor(0.0, 0.0), &floor(5.0, -2.0)));
        // Nothing behind both corners.
        assert!(one_surface(&None, &None));
        // The floor against the background, another object, another material.
        assert!(!one_surface(&floor(0.0, 0.0), &None));
        assert!(!one_surface(&None, &floor(0.0, 0.0)));
        assert!(!one_surface(&floor(0.0, 0.0), &hit(Vec3::X, Vec3::Y, 4, 1)));
        assert!(!one_surface(&floor(0.0, 0.0), &hit(Vec3::X, Vec3::Y, 3, 2)));
        // A crease (a box's two faces: one object and material) and a step (a parallel plane
        // a little higher).
        assert!(!one_surface(&floor(0.0, 0.0), &hit(Vec3::X, Vec3::X, 3, 1)));
        let tilted = Vec3::new(0.0, 1.0, 0.2).normalize();
        assert!(!one_surface(&floor(0.0, 0.0), &hit(Vec3::X, tilted, 3, 1)));
        assert!(!one_surface(
            &floor(0.0, 0.0),
            &hit(Vec3::new(1.0, 0.1, 0.0), Vec3::Y, 3, 1)
        ));
    }
}
