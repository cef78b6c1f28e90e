//! The scene's objects as entities: each object of the scene ([`crate::scene::Object`]: an
//! OBJ object, a glTF node's mesh, a scene file's mesh entry, a grid's copy) is an entity with
//! a [`SceneObject`], a `Name` and a `Transform`, spawned whenever a scene is installed.
//! Changing an object's `Transform` (the keys below, the inspector, or any system) installs
//! the scene with that object placed there: a placement is moved, and the BVH system builds
//! the top level again and keeps every mesh's tree ([`super::bvh`]); an object among the
//! scene's own triangles is first lifted out of them into a mesh of its own
//! ([`crate::scene::Scene::lifted`]), which builds the own triangles' tree and the new
//! mesh's once. The picture starts over (no sample of the old place is kept).
//!
//! A click selects the object under the pointer (its box drawn, its name and triangles in the
//! inspector); the arrow keys move it across the floor, Page Up / Page Down up and down,
//! Z / X turn it, - / = scale it, Escape lets it go.

use bevy::prelude::*;
use glam::Affine3A;

use crate::geometry::Aabb;
use crate::scene::Place;

use super::UiFocus;
use super::bvh::SceneBvh;
use super::debug_ray::{DebugRaySystems, ShootRay, ray_through};
use super::scene::{CurrentScene, SceneLoading, SceneSystems};
use super::trace::{TraceCamera, ViewSettings, ViewportSize};

/// Spawns the objects of each scene, installs moved placements, and (interactive) picks and
/// moves them.
pub struct ObjectsPlugin {
    /// Read clicks and keys and draw the selection (false under `MinimalPlugins`).
    pub interactive: bool,
}

impl Plugin for ObjectsPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<Selection>()
            .init_resource::<Spawned>()
            .add_systems(
                PreUpdate,
                (spawn_objects, install_moves)
                    .chain()
                    .in_set(ObjectSystems)
                    .after(SceneSystems),
            );
        if self.interactive {
            // After the debug ray: the camera has taken a new scene's view by then.
            app.add_systems(
                Update,
                (pick, move_keys, draw_selection)
                    .chain()
                    .after(DebugRaySystems),
            );
        }
    }
}

/// The object systems (spawning and installing moves), which the BVH system runs after.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub struct ObjectSystems;

/// One of the scene's objects.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct SceneObject {
    /// Its index in [`crate::scene::Scene::objects`].
    pub object: usize,
    /// Its triangles.
    pub triangles: usize,
    /// Its box in its own frame (where its `Transform` carries it).
    pub bounds: Aabb,
    /// The `Transform` it was spawned with, and the frame the scene gave it then: while the
    /// object stands there, only a change from that `Transform` moves it (a transform with
    /// shear, which a `Transform` cannot hold, stays as the file gave it until the object is
    /// moved).
    spawned: (Transform, Affine3A),
}

/// The object the user picked, if any.
#[derive(Resource, Default, Clone, Copy, Debug, PartialEq, Eq)]
pub struct Selection(pub Option<Entity>);

/// The generation of the scene whose objects are spawned.
#[derive(Resource, Default)]
struct Spawned(Option<u64>);

/// Despawns the previous scene's objects and spawns the new one's, when a scene other than
/// one made here by moving an object is installed.
fn spawn_objects(
    mut commands: Commands,
    current: Res<CurrentScene>,
    mut spawned: ResMut<Spawned>,
    mut selection: ResMut<Selection>,
    objects: Query<Entity, With<SceneObject>>,
) {
    if spawned.0 == Some(current.generation) {
        return;
    }
    let ours = current.moved_from.is_some() && current.moved_from == spawned.0;
    spawned.0 = Some(current.generation);
    if ours {
        return;
    }
    for e in &objects {
        commands.entity(e).despawn();
    }
    selection.0 = None;
    let scene = &current.scene;
    for (i, o) in scene.objects.iter().enumerate() {
        let Some((frame, bounds)) = scene.object_frame(i) else {
            continue;
        };
        let triangles = match o.place {
            Place::Own { count, .. } => count as usize,
            Place::Placed(p) => scene.instances.placements().get(p).map_or(0, |p| {
                scene.instances.meshes[p.mesh as usize].triangles.len()
            }),
        };
        let transform = Transform::from_matrix(Mat4::from(frame));
        commands.spawn((
            SceneObject {
                object: i,
                triangles,
                bounds,
                spawned: (transform, frame),
            },
            transform,
            Name::new(o.name.clone()),
        ));
    }
}

/// Installs the scene with the objects whose `Transform` changed (and differs from what they
/// were spawned with) placed there, once per frame however many moved: placements moved,
/// objects among the scene's own triangles lifted out of them.
fn install_moves(
    mut current: ResMut<CurrentScene>,
    mut spawned: ResMut<Spawned>,
    objects: Query<(&SceneObject, &Transform), Changed<Transform>>,
) {
    if spawned.0 != Some(current.generation) {
        return;
    }
    let scene = &current.scene;
    let moves: Vec<(usize, Affine3A)> = objects
        .iter()
        .filter(|(o, t)| {
            **t != o.spawned.0 || scene.object_frame(o.object).map(|f| f.0) != Some(o.spawned.1)
        })
        .map(|(o, t)| (o.object, t.compute_affine()))
        .filter(|(i, m)| scene.object_frame(*i).map(|f| f.0) != Some(*m))
        .collect();
    if moves.is_empty() {
        return;
    }
    let placement = |i: usize| match scene.objects[i].place {
        Place::Placed(p) => Some(p),
        Place::Own { .. } => None,
    };
    let placed: Vec<(usize, Affine3A)> = moves
        .iter()
        .filter_map(|&(i, m)| placement(i).map(|p| (p, m)))
        .collect();
    let lift: Vec<(usize, Affine3A)> = moves
        .iter()
        .copied()
        .filter(|&(i, _)| placement(i).is_none())
        .collect();
    let edited = scene.instances.moved(&placed).and_then(|instances| {
        let mut edited = (**scene).clone();
        edited.instances = instances;
        lift.iter().try_fold(edited, |s, &(i, m)| s.lifted(i, m))
    });
    let edited = match edited {
        Ok(s) => s,
        Err(e) => {
            warn!("object not moved: {e}");
            return;
        }
    };
    for &(i, _) in &lift {
        info!(
            "{} lifted out of the scene's own triangles into a mesh of its own",
            edited.objects[i].name
        );
    }
    let from = current.generation;
    current.scene = std::sync::Arc::new(edited);
    current.generation += 1;
    current.reframe = false;
    current.moved_from = Some(from);
    current.lifted = !lift.is_empty();
    spawned.0 = Some(current.generation);
}

/// A click selects the object whose triangle the pixel's ray meets first (or none).
#[allow(clippy::too_many_arguments)]
fn pick(
    mut shots: MessageReader<ShootRay>,
    current: Res<CurrentScene>,
    bvh: Res<SceneBvh>,
    viewport: Res<ViewportSize>,
    settings: Res<ViewSettings>,
    camera: Query<(&Transform, &Projection), With<TraceCamera>>,
    objects: Query<(Entity, &SceneObject)>,
    mut selection: ResMut<Selection>,
    (loading, mut pending): (Res<SceneLoading>, Local<Option<Vec2>>),
) {
    // A click before the scene and its trees are ready (`view --ray`) picks once they are.
    if let Some(ShootRay(p)) = shots.read().last().copied() {
        *pending = Some(p);
    }
    let Some(p) = *pending else {
        return;
    };
    let (Ok((transform, projection)), Some(tree)) =
        (camera.single(), bvh.tracing(current.generation))
    else {
        return;
    };
    if loading.current().is_some() {
        return;
    }
    *pending = None;
    let ray = ray_through(transform, projection, viewport.0, &settings, p);
    let object = tree
        .intersect(&ray, f32::INFINITY)
        .and_then(|h| current.scene.object_of(h.prim));
    selection.0 = object.and_then(|i| objects.iter().find(|(_, o)| o.object == i).map(|(e, _)| e));
    if let (Some(i), Some(_)) = (object, selection.0) {
        info!("picked {}", current.scene.objects[i].name);
    }
}

/// Moves, turns and scales the selected object by keys: a step is a twentieth of its size.
fn move_keys(
    input: Res<ButtonInput<KeyCode>>,
    focus: Res<UiFocus>,
    mut selection: ResMut<Selection>,
    mut objects: Query<(&SceneObject, &mut Transform)>,
) {
    let Some(e) = selection.0 else {
        return;
    };
    if focus.keyboard {
        return;
    }
    if input.just_pressed(KeyCode::Escape) {
        selection.0 = None;
        return;
    }
    let Ok((object, mut t)) = objects.get_mut(e) else {
        selection.0 = None;
        return;
    };
    let b = &object.bounds;
    let size = if b.is_empty() {
        1.0
    } else {
        (Vec3::from(b.max) - Vec3::from(b.min)).length() * t.scale.max_element()
    };
    let step = (size / 20.0).max(1e-6);
    let mut moved = *t;
    for (key, by) in [
        (KeyCode::ArrowLeft, Vec3::NEG_X),
        (KeyCode::ArrowRight, Vec3::X),
        (KeyCode::ArrowUp, Vec3::NEG_Z),
        (KeyCode::ArrowDown, Vec3::Z),
        (KeyCode::PageUp, Vec3::Y),
        (KeyCode::PageDown, Vec3::NEG_Y),
    ] {
        if input.just_pressed(key) {
            moved.translation += by * step;
        }
    }
    for (key, angle) in [(KeyCode::KeyZ, 15.0f32), (KeyCode::KeyX, -15.0)] {
        if input.just_pressed(key) {
            moved.rotate_y(angle.to_radians());
        }
    }
    for (key, factor) in [(KeyCode::Minus, 1.0 / 1.1f32), (KeyCode::Equal, 1.1)] {
        if input.just_pressed(key) {
            moved.scale *= factor;
        }
    }
    if moved != *t {
        *t = moved;
    }
}

/// The selected object's box (its box in its own frame, carried by its `Transform`), in
/// yellow.
fn draw_selection(
    selection: Res<Selection>,
    objects: Query<(&SceneObject, &Transform)>,
    mut gizmos: Gizmos,
) {
    let Some((o, t)) = selection.0.and_then(|e| objects.get(e).ok()) else {
        return;
    };
    if o.bounds.is_empty() {
        return;
    }
    let (lo, hi) = (Vec3::from(o.bounds.min), Vec3::from(o.bounds.max));
    let box_to_world = t.compute_affine()
        * Affine3A::from_scale_rotation_translation(hi - lo, Quat::IDENTITY, (lo + hi) * 0.5);
    gizmos.cube(box_to_world, Color::srgb(1.0, 0.85, 0.1));
}
