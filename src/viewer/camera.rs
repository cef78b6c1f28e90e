//! Flying the camera: Bevy's free camera, its speed scaled to the scene, placed at the scene's
//! own camera whenever a scene arrives, and deaf while the pointer or keyboard is busy with
//! the inspector.

use bevy::camera_controller::free_camera::{FreeCamera, FreeCameraPlugin, FreeCameraState};
use bevy::prelude::*;

use super::UiFocus;
use super::scene::{CurrentScene, SceneSystems};
use crate::scene::Camera as SceneCamera;

/// Adds the free camera and keeps it in step with the scene and the inspector.
pub struct FlyCameraPlugin;

impl Plugin for FlyCameraPlugin {
    fn build(&self, app: &mut App) {
        app.add_plugins(FreeCameraPlugin)
            .add_systems(PreUpdate, place_at_scene_camera.after(SceneSystems))
            .add_systems(PreUpdate, gate_camera_input);
    }
}

/// Marks the camera that flies (the trace camera).
#[derive(Component, Default)]
pub struct FlyCamera;

/// The transform and projection that show `camera` as the scene file describes it.
pub fn pose_of(camera: &SceneCamera) -> (Transform, Projection) {
    // The headless renderer's own rotation (not Bevy's `looking_at`, which rounds
    // differently): the still picture from the scene's camera is the headless render's, bit
    // for bit, for every camera.
    let transform = Transform::from_translation(camera.position)
        .with_rotation(crate::camera::look_rotation(camera));
    let projection = Projection::Perspective(PerspectiveProjection {
        fov: camera.vfov_deg.clamp(1.0, 170.0).to_radians(),
        ..default()
    });
    (transform, projection)
}

/// Size of the scene: half the diagonal of its bounds (1 for an empty scene).
pub fn scene_radius(current: &CurrentScene) -> f32 {
    let b = current.scene.mesh.bounds();
    let r = if b.is_empty() {
        1.0
    } else {
        (Vec3::from(b.max) - Vec3::from(b.min)).length() * 0.5
    };
    if r.is_finite() && r > 0.0 { r } else { 1.0 }
}

fn place_at_scene_camera(
    mut commands: Commands,
    current: Res<CurrentScene>,
    mut cameras: Query<(Entity, &mut Transform, &mut Projection), With<FlyCamera>>,
    added: Query<(), Added<FlyCamera>>,
) {
    // Another instant of the same file keeps the camera where the user has it.
    if !(current.is_changed() && current.reframe) && added.is_empty() {
        return;
    }
    let (transform, projection) = pose_of(&current.scene.camera);
    let radius = scene_radius(&current);
    for (entity, mut t, mut p) in &mut cameras {
        *t = transform;
        if let (Projection::Perspective(old), Projection::Perspective(new)) = (&mut *p, &projection)
        {
            old.fov = new.fov;
            // Near plane small against the scene, so gizmos close to the eye still show.
            old.near = (radius * 1e-3).max(1e-5);
        }
        // A fresh state takes its yaw and pitch from the new transform.
        commands.entity(entity).insert((
            FreeCamera {
                walk_speed: radius * 0.5,
                run_speed: radius * 2.0,
                ..default()
            },
            FreeCameraState::default(),
        ));
    }
}

fn gate_camera_input(
    focus: Res<UiFocus>,
    mut states: Query<&mut FreeCameraState, With<FlyCamera>>,
) {
    for mut s in &mut states {
        // The inspector has the pointer or the keyboard: the camera leaves them to it.
        let enabled = !(focus.pointer || focus.keyboard);
        if s.enabled != enabled {
            s.enabled = enabled;
        }
    }
}
