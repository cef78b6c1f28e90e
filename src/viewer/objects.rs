//! The scene's objects as entities: each placement of a mesh the scene holds once
//! ([`crate::scene::Instances`]) is an entity with a [`SceneObject`], a `Name` and a
//! `Transform` (the placement), spawned whenever a scene is installed. Changing an object's
//! `Transform` (the keys below, the inspector, or any system) installs the scene with that
//! placement moved: the BVH system then builds the top level again and keeps every mesh's
//! tree ([`super::bvh`]), and the picture starts over (no sample of the old place is kept).
//!
//! A click selects the object under the pointer (its box drawn, its name and triangles in the
//! inspector); the arrow keys move it across the floor, Page Up / Page Down up and down,
//! Z / X turn it, - / = scale it, Escape lets it go.

use bevy::prelude::*;
use glam::Affine3A;

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

/// A placement of one of the scene's shared meshes.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct SceneObject {
    /// Its index in the scene's placements.
    pub placement: usize,
    /// The mesh it places (an index into the scene's shared meshes).
    pub mesh: u32,
    /// Triangles of that mesh.
    pub triangles: usize,
    /// The `Transform` it was spawned with: only a change from it moves the placement (a
    /// transform with shear, which a `Transform` cannot hold, stays as the file gave it
    /// until the object is moved).
    spawned: Transform,
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
    let placed = &current.scene.instances;
    for (i, p) in placed.placements().iter().enumerate() {
        let mesh = &placed.meshes[p.mesh as usize];
        let transform = Transform::from_matrix(Mat4::from(p.to_world));
        commands.spawn((
            SceneObject {
                placement: i,
                mesh: p.mesh,
                triangles: mesh.triangles.len(),
                spawned: transform,
            },
            transform,
            Name::new(format!("mesh {} #{i}", p.mesh)),
        ));
    }
}

/// Installs the scene with the placements of the objects whose `Transform` changed (and
/// differs from what they were spawned with), once per frame however many moved.
fn install_moves(
    mut current: ResMut<CurrentScene>,
    mut spawned: ResMut<Spawned>,
    objects: Query<(&SceneObject, &Transform), Changed<Transform>>,
) {
    if spawned.0 != Some(current.generation) {
        return;
    }
    let moves: Vec<(usize, Affine3A)> = objects
        .iter()
        .filter(|(o, t)| **t != o.spawned)
        .map(|(o, t)| (o.placement, t.compute_affine()))
        .filter(|(i, m)| {
            current
                .scene
                .instances
                .placements()
                .get(*i)
                .map(|p| p.to_world)
                != Some(*m)
        })
        .collect();
    if moves.is_empty() {
        return;
    }
    let instances = match current.scene.instances.moved(&moves) {
        Ok(i) => i,
        Err(e) => {
            warn!("object not moved: {e}");
            return;
        }
    };
    let mut scene = (*current.scene).clone();
    scene.instances = instances;
    let from = current.generation;
    current.scene = std::sync::Arc::new(scene);
    current.generation += 1;
    current.reframe = false;
    current.moved_from = Some(from);
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
    let own = current.scene.mesh.triangles.len() as u32;
    let placement = tree
        .intersect(&ray, f32::INFINITY)
        .filter(|h| h.prim >= own)
        .map(|h| current.scene.instances.placement_of(h.prim - own));
    selection.0 = placement.and_then(|i| {
        objects
            .iter()
            .find(|(_, o)| o.placement == i)
            .map(|(e, _)| e)
    });
    if let (Some(i), Some(_)) = (placement, selection.0) {
        info!("picked placement {i}");
    }
}

/// Moves, turns and scales the selected object by keys: a step is a twentieth of its size.
fn move_keys(
    input: Res<ButtonInput<KeyCode>>,
    focus: Res<UiFocus>,
    mut selection: ResMut<Selection>,
    current: Res<CurrentScene>,
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
    let size = current
        .scene
        .instances
        .meshes
        .get(object.mesh as usize)
        .map_or(1.0, |m| {
            let b = m.bounds();
            (Vec3::from(b.max) - Vec3::from(b.min)).length() * t.scale.max_element()
        });
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

/// The selected object's box (its mesh's box carried by its placement), in yellow.
fn draw_selection(
    selection: Res<Selection>,
    current: Res<CurrentScene>,
    objects: Query<&SceneObject>,
    mut gizmos: Gizmos,
) {
    let Some(o) = selection.0.and_then(|e| objects.get(e).ok()) else {
        return;
    };
    let placed = &current.scene.instances;
    let (Some(p), Some(mesh)) = (
        placed.placements().get(o.placement),
        placed.meshes.get(o.mesh as usize),
    ) else {
        return;
    };
    let b = mesh.bounds();
    let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
    let box_to_world = p.to_world
        * Affine3A::from_scale_rotation_translation(hi - lo, Quat::IDENTITY, (lo + hi) * 0.5);
    gizmos.cube(box_to_world, Color::srgb(1.0, 0.85, 0.1));
}
