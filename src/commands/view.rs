//! Which view a render uses: the glTF camera if the scene has one, else an automatic view of
//! the bounds; then every Radiance view option given on the command line overrides its part.
//! Positions given (cameras, -vp) are in world coordinates; the view holds them relative to
//! the scene's tracing origin.

use crate::cli::ViewArgs;
use crate::scene::Scene;
use crate::scene::auto_view::{Probe, auto_view_scored};
use crate::scene::view::{Projection, View};
use crate::tracer::Tracer;
use glam::{DVec3, Vec3};

fn vec3(v: &[f32]) -> Vec3 {
    Vec3::new(v[0], v[1], v[2])
}

/// Below this share of lit probe rays an automatic view is said to be mostly dark.
const DARK_AUTO_VIEW: f32 = 0.1;

/// The view, and a warning when it is an automatic view that sees little lit surface. `time`:
/// the scene time (seconds) of a frame, where the camera's animation places it; None for a
/// still image, which takes the camera where the file puts it at rest.
pub fn choose_view(
    scene: &Scene,
    tracer: &Tracer,
    args: &ViewArgs,
    width: u32,
    height: u32,
    time: Option<f64>,
) -> Result<(View, Option<String>), String> {
    let aspect = width as f32 / height as f32;
    let mut note = None;
    let camera = match time {
        Some(t) if !scene.cameras.is_empty() => Some(scene.camera_at(0, t)),
        _ => scene.cameras.first().cloned(),
    };
    let mut view = match camera.as_ref() {
        Some(c) if c.perspective => {
            let vertical = c.yfov.to_degrees();
            View {
                projection: Projection::Perspective,
                position: scene.to_tracing(DVec3::from(c.position)),
                direction: Vec3::from(c.forward),
                up: Vec3::from(c.up),
                horizontal: View::horizontal_for_aspect(Projection::Perspective, vertical, aspect),
                vertical,
            }
        }
        Some(c) => View {
            projection: Projection::Parallel,
            position: scene.to_tracing(DVec3::from(c.position)),
            direction: Vec3::from(c.forward),
            up: Vec3::from(c.up),
            horizontal: 2.0 * c.ymag * aspect,
            vertical: 2.0 * c.ymag,
        },
        None => {
            let (view, lit) = auto_view_scored(scene.bounds_min, scene.bounds_max, aspect, |o, d| {
                probe(scene, tracer, o, d)
            });
            if lit < DARK_AUTO_VIEW && args.vp.is_none() {
                let (lo, hi) = (scene.to_world(scene.bounds_min), scene.to_world(scene.bounds_max));
                note = Some(format!(
                    "the scene has no camera and the automatic view sees little lit surface ({:.0} % of its probe \
                     rays): the image will be mostly dark; give a view inside the scene's bounds ({:.6}, {:.6}, \
                     {:.6}) .. ({:.6}, {:.6}, {:.6}), e.g. -vp X Y Z -vd 1 0 0",
                    100.0 * lit,
                    lo.x,
                    lo.y,
                    lo.z,
                    hi.x,
                    hi.y,
                    hi.z
                ));
            }
            view
        }
    };
    if args.vtl {
        view.projection = Projection::Parallel;
    } else if args.vtv {
        view.projection = Projection::Perspective;
    }
    if let Some(p) = &args.vp {
        view.position = scene.to_tracing(DVec3::new(p[0], p[1], p[2]));
    }
    if let Some(d) = &args.vd {
        view.direction = vec3(d);
    }
    if let Some(u) = &args.vu {
        view.up = vec3(u);
    }
    // One angle given: the other follows from the image's aspect, so pixels stay square.
    match (args.vh, args.vv) {
        (Some(h), Some(v)) => {
            (view.horizontal, view.vertical) = (h, v);
            let square_h = View::horizontal_for_aspect(view.projection, v, aspect);
            let pixel_aspect = view.camera(width, height).pixel_aspect();
            if (pixel_aspect - 1.0).abs() > 1e-3 {
                note = Some(format!(
                    "-vh {h} with -vv {v} at {width}x{height} makes pixels {pixel_aspect:.4} times as wide as high \
                     (the EXR's PixelAspectRatio says so); give one of the two (-vh {square_h:.4} goes with -vv {v}) \
                     to keep pixels square"
                ));
            }
        }
        (Some(h), None) => {
            view.horizontal = h;
            view.vertical = View::horizontal_for_aspect(view.projection, h, 1.0 / aspect);
        }
        (None, Some(v)) => {
            view.vertical = v;
            view.horizontal = View::horizontal_for_aspect(view.projection, v, aspect);
        }
        (None, None) => {}
    }
    view.validate()?;
    Ok((view, note))
}

/// Light positions the automatic view tests visibility against: every punctual light and an
/// even selection of emissive triangles' centres.
fn light_positions(scene: &Scene) -> Vec<Vec3> {
    const MAX_EMITTERS: usize = 32;
    let emitters = &scene.emitters.triangles;
    let step = emitters.len().div_ceil(MAX_EMITTERS).max(1);
    let centres = emitters
        .iter()
        .step_by(step)
        .map(|t| t.p0 + (t.e1 + t.e2) / 3.0 + t.normal * 1e-3 * scene.size());
    scene
        .punctual_lights
        .iter()
        .map(|l| l.position)
        .chain(centres)
        .collect()
}

fn probe(scene: &Scene, tracer: &Tracer, origin: Vec3, dir: Vec3) -> Option<Probe> {
    let distance = tracer.hit_distance(origin, dir)?;
    let point = origin + dir * distance * 0.999;
    let lit = light_positions(scene)
        .into_iter()
        .any(|light| !tracer.segment_blocked(point, light));
    Some(Probe { distance, lit })
}
