//! The debug ray: click a pixel to shoot its ray; the path is drawn with every bounce, the
//! normal at each hit, the shadow ray to each light coloured by what passes, and the BVH
//! nodes the ray entered (dim red where it found nothing): in a scene that places meshes, the
//! top level's boxes and those of each placed mesh's tree it walked, carried by the placement.

use bevy::prelude::*;
use glam::Affine3A;

use super::UiFocus;
use super::bvh::SceneBvh;
use super::scene::{CurrentScene, SceneLoading};
use super::trace::{LoadedEnvironment, TraceCamera, TraceSystems, ViewSettings, ViewportSize};
use crate::bvh::Tree;
use crate::geometry::Ray;
use crate::render::Tracer;
use crate::render::debug::{DebugPath, SegmentKind, ShadowState};

/// Shoots debug rays (on click, or on a [`ShootRay`] message) and draws them.
pub struct DebugRayPlugin {
    /// Read the mouse and keys and draw the gizmos (off in windowless apps, which send
    /// [`ShootRay`] themselves and read [`DebugRay`]).
    pub interactive: bool,
}

impl Plugin for DebugRayPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<DebugRay>()
            .add_message::<ShootRay>()
            .add_message::<PickFocus>()
            .init_resource::<FocusPicking>();
        if self.interactive {
            app.init_gizmo_group::<DebugRayGizmos>().add_systems(
                Update,
                (click, keys, shoot.in_set(DebugRaySystems), draw)
                    .chain()
                    .after(TraceSystems),
            );
        } else {
            app.add_systems(Update, shoot.in_set(DebugRaySystems).after(TraceSystems));
        }
    }
}

/// The system that shoots debug rays, for ordering.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub struct DebugRaySystems;

/// The debug-ray drawing (key R).
#[derive(Default, Reflect, GizmoConfigGroup)]
pub struct DebugRayGizmos;

/// Shoot the ray through this point of the window, in physical pixels from the top left.
#[derive(Message, Clone, Copy, Debug)]
pub struct ShootRay(pub Vec2);

/// Set the focus distance to what lies under this point of the window (physical pixels).
#[derive(Message, Clone, Copy, Debug)]
pub struct PickFocus(pub Vec2);

/// True while the next click picks the focus instead of shooting a debug ray.
#[derive(Resource, Default)]
pub struct FocusPicking(pub bool);

/// The last debug ray.
#[derive(Resource, Default)]
pub struct DebugRay {
    /// Where it was shot (physical window pixels).
    pub pixel: Option<Vec2>,
    /// Its path.
    pub path: DebugPath,
    /// Show the BVH nodes each segment entered.
    pub show_nodes: bool,
    /// A ray asked for before the scene and its BVH were ready; shot once they are.
    pub pending: Option<Vec2>,
}

fn click(
    mouse: Res<ButtonInput<MouseButton>>,
    focus: Res<UiFocus>,
    windows: Query<&Window>,
    mut picking: ResMut<FocusPicking>,
    mut shoot: MessageWriter<ShootRay>,
    mut pick: MessageWriter<PickFocus>,
) {
    if focus.pointer || !mouse.just_pressed(MouseButton::Left) {
        return;
    }
    let Some(p) = windows.iter().find_map(|w| w.physical_cursor_position()) else {
        return;
    };
    if picking.0 {
        picking.0 = false;
        pick.write(PickFocus(p));
    } else {
        shoot.write(ShootRay(p));
    }
}

fn keys(
    input: Res<ButtonInput<KeyCode>>,
    focus: Res<UiFocus>,
    mut store: ResMut<GizmoConfigStore>,
    mut picking: ResMut<FocusPicking>,
) {
    if focus.keyboard {
        return;
    }
    if input.just_pressed(KeyCode::KeyR) {
        let c = &mut store.config_mut::<DebugRayGizmos>().0.enabled;
        *c = !*c;
    }
    if input.just_pressed(KeyCode::KeyF) {
        picking.0 = !picking.0;
    }
}

/// The camera ray through window point `p` (physical pixels), exactly as the tracer makes it
/// for a pixel centre at full resolution.
pub fn ray_through(
    transform: &Transform,
    projection: &Projection,
    viewport: UVec2,
    settings: &ViewSettings,
    p: Vec2,
) -> Ray {
    let cam = super::trace::camera_rays(
        transform,
        projection,
        viewport,
        &ViewSettings {
            depth_of_field: false,
            ..settings.clone()
        },
    );
    cam.pinhole(p.x, p.y)
}

#[allow(clippy::too_many_arguments)]
fn shoot(
    mut shots: MessageReader<ShootRay>,
    mut picks: MessageReader<PickFocus>,
    current: Res<CurrentScene>,
    loading: Res<SceneLoading>,
    bvh: Res<SceneBvh>,
    env: Res<LoadedEnvironment>,
    viewport: Res<ViewportSize>,
    camera: Query<(&Transform, &Projection), With<TraceCamera>>,
    mut settings: ResMut<ViewSettings>,
    mut debug: ResMut<DebugRay>,
    store: Option<ResMut<GizmoConfigStore>>,
) {
    if let Some(ShootRay(p)) = shots.read().last().copied() {
        debug.pending = Some(p);
    }
    let (Ok((transform, projection)), Some(tree)) =
        (camera.single(), bvh.tracing(current.generation))
    else {
        picks.clear();
        return;
    };
    if loading.current().is_some() {
        return; // a new scene is on its way: shoot into that one
    }
    let tracer = Tracer::new(
        &current.scene,
        tree,
        settings.plan(&current.scene),
        settings.max_depth,
        &env.map,
    );
    if let Some(p) = debug.pending.take() {
        let ray = ray_through(transform, projection, viewport.0, &settings, p);
        debug.path = tracer.debug_path(&ray);
        debug.pixel = Some(p);
        if let Some(mut store) = store {
            store.config_mut::<DebugRayGizmos>().0.enabled = true;
        }
    }
    if let Some(PickFocus(p)) = picks.read().last().copied() {
        let ray = ray_through(transform, projection, viewport.0, &settings, p);
        if let Some(hit) = tree.intersect(&ray, f32::INFINITY) {
            // Focus is measured along the view axis (the plane in focus faces the camera).
            let forward = transform.rotation * Vec3::NEG_Z;
            let d = hit.t * ray.dir.normalize().dot(forward);
            if d.is_finite() && d > 0.0 {
                settings.focus_distance = d;
                settings.depth_of_field = true;
            }
        }
    }
}

/// Colour of a path segment by how it began.
pub fn segment_color(kind: SegmentKind) -> Color {
    match kind {
        SegmentKind::Camera => Color::srgb(1.0, 1.0, 0.2),
        SegmentKind::Reflection => Color::srgb(0.2, 0.9, 1.0),
        SegmentKind::Transmission => Color::srgb(1.0, 0.4, 1.0),
    }
}

/// Colour of a shadow ray: green visible, red blocked, orange attenuated.
pub fn shadow_color(state: ShadowState) -> Color {
    match state {
        ShadowState::Visible => Color::srgb(0.2, 1.0, 0.3),
        ShadowState::Blocked => Color::srgb(1.0, 0.15, 0.1),
        ShadowState::Attenuated => Color::srgb(1.0, 0.6, 0.1),
    }
}

fn draw(
    mut gizmos: Gizmos<DebugRayGizmos>,
    debug: Res<DebugRay>,
    current: Res<CurrentScene>,
    bvh: Res<SceneBvh>,
) {
    if !gizmos.config.enabled || debug.pixel.is_none() {
        return;
    }
    let radius = super::camera::scene_radius(&current);
    let normal_len = radius * 0.08;
    for seg in &debug.path.segments {
        let end = match seg.hit {
            Some(h) => h.point,
            None => seg.ray.origin + seg.ray.dir * radius * 3.0,
        };
        gizmos.line(seg.ray.origin, end, segment_color(seg.kind));
        if let Some(h) = seg.hit {
            gizmos.arrow(
                h.point,
                h.point + h.normal * normal_len,
                Color::srgb(0.3, 0.5, 1.0),
            );
            gizmos.sphere(
                Isometry3d::from_translation(h.point),
                radius * 0.006,
                Color::WHITE,
            );
        }
    }
    for s in &debug.path.shadows {
        gizmos.line(s.from, s.to, shadow_color(s.state()));
    }
    if debug.show_nodes
        && let Some(tree) = bvh.tracing(current.generation)
    {
        for seg in &debug.path.segments {
            for n in &seg.nodes {
                let c = if n.found_hit {
                    Color::srgba(1.0, 1.0, 1.0, 0.7)
                } else {
                    Color::srgba(1.0, 0.25, 0.25, 0.45)
                };
                // A box of the scene's tree or of the top level is drawn as it is; one of a
                // placed mesh's tree is carried by its placement.
                let (b, to_world) = match (tree, n.instance) {
                    (Tree::Flat(b), _) => (b.nodes[n.index as usize].aabb(), Affine3A::IDENTITY),
                    (Tree::TwoLevel(t), None) => {
                        (t.top_nodes()[n.index as usize].aabb(), Affine3A::IDENTITY)
                    }
                    (Tree::TwoLevel(t), Some(i)) => {
                        let mesh = &t.meshes[t.mesh_of(i as usize) as usize];
                        (
                            mesh.nodes[n.index as usize].aabb(),
                            t.to_mesh(i as usize).inverse(),
                        )
                    }
                };
                let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
                gizmos.cube(
                    to_world
                        * Affine3A::from_scale_rotation_translation(
                            hi - lo,
                            Quat::IDENTITY,
                            (lo + hi) * 0.5,
                        ),
                    c,
                );
            }
        }
    }
}
