//! The real-time viewer (Bevy): fly through a scene while the CPU ray tracer refines the
//! image, with BVH and debug-ray gizmos and an inspector.
//!
//! One plugin per concern: [`scene::ScenePlugin`] (loading off the frame),
//! [`bvh::BvhPlugin`] (rebuilding the BVH when the scene or its settings change),
//! [`trace::TracePlugin`] (the ray-trace system), [`display::DisplayPlugin`] (the traced
//! image on screen), [`camera::FlyCameraPlugin`], [`gizmos::BvhGizmoPlugin`],
//! [`debug_ray::DebugRayPlugin`], [`animation::AnimationPlugin`] (the glTF animations'
//! timeline), [`objects::ObjectsPlugin`] (placed meshes as entities: picked and moved),
//! [`inspector::InspectorPlugin`],
//! [`pacing::PacingPlugin`] (continuous updates only while something changes),
//! [`panel_cache::PanelCachePlugin`] (the inspector's pixels reused while it does not change)
//! and [`capture::CapturePlugin`] (PNG, screenshots, scripted runs). The tracing itself runs on the
//! trace worker ([`worker`]), off the schedule. [`CorePlugins`] is the part
//! that needs no window, for tests with `MinimalPlugins`.

pub mod animation;
pub mod bvh;
pub mod camera;
pub mod capture;
pub mod debug_ray;
pub mod display;
pub mod gizmos;
pub mod inspector;
pub mod objects;
mod orbit;
pub mod pacing;
pub mod panel_cache;
pub mod scene;
pub mod still_denoise;
pub mod task;
pub mod trace;
pub mod worker;

use std::path::PathBuf;

use bevy::app::TaskPoolThreadAssignmentPolicy;
use bevy::prelude::*;
use bevy::window::{PresentMode, WindowResolution};
use bevy_egui::{EguiGlobalSettings, EguiPlugin, PrimaryEguiContext};

use crate::bvh::BuildOptions;

/// Whether the inspector has the pointer or the keyboard (then the camera, clicks and keys
/// leave them to it).
#[derive(Resource, Default, Clone, Copy, Debug, PartialEq, Eq)]
pub struct UiFocus {
    /// The pointer is over or dragging an inspector widget.
    pub pointer: bool,
    /// A text field has the keyboard.
    pub keyboard: bool,
}

/// Width of the inspector's side panel in physical pixels (0 while hidden): the picture
/// fills the rest of the window.
#[derive(Resource, Default, Clone, Copy, Debug, PartialEq, Eq)]
pub struct PanelWidth(pub u32);

/// How the viewer starts.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// Scene file, OBJ, PLY or glTF (`None`: the built-in Cornell box).
    pub scene: Option<PathBuf>,
    /// Window size in pixels.
    pub window: UVec2,
    /// BVH settings at start.
    pub bvh: BuildOptions,
    /// Render settings at start.
    pub settings: trace::ViewSettings,
    /// Show the inspector and status line.
    pub inspector: bool,
    /// Gizmo groups on at start: BVH level, leaves, debug ray.
    pub gizmos: StartGizmos,
    /// Leaf view at start.
    pub leaves: gizmos::LeafView,
    /// Debug ray to shoot at start (window pixel).
    pub ray: Option<Vec2>,
    /// Camera pose (eye, target) to take once the scene is up and the start ray is shot.
    pub look: Option<(Vec3, Vec3)>,
    /// Scripted run (`--frames`).
    pub script: Option<capture::CaptureScript>,
    /// Where the animation's timeline starts (seconds), and whether it plays.
    pub animation: (f64, bool),
}

/// Which gizmo groups are on at start.
#[derive(Clone, Copy, Debug, Default)]
pub struct StartGizmos {
    /// BVH level boxes.
    pub level: bool,
    /// Leaves.
    pub leaves: bool,
    /// The nodes the debug ray entered.
    pub ray_nodes: bool,
}

/// The plugins that need no window: scene, BVH, tracing and the debug ray's data. Tests run
/// them under `MinimalPlugins`; the viewer adds the window, display, camera, gizmos and UI.
pub struct CorePlugins {
    /// Scene to load at start.
    pub scene: Option<PathBuf>,
    /// BVH settings at start.
    pub bvh: BuildOptions,
    /// Render settings at start.
    pub settings: trace::ViewSettings,
    /// Size of the image until a window gives one.
    pub viewport: UVec2,
    /// Read input and draw gizmos (false under `MinimalPlugins`).
    pub interactive: bool,
}

impl Plugin for CorePlugins {
    fn build(&self, app: &mut App) {
        app.init_resource::<UiFocus>()
            .init_resource::<PanelWidth>()
            .add_plugins((
                scene::ScenePlugin {
                    initial: self.scene.clone(),
                },
                bvh::BvhPlugin { options: self.bvh },
                trace::TracePlugin {
                    settings: self.settings.clone(),
                    viewport: self.viewport,
                },
                debug_ray::DebugRayPlugin {
                    interactive: self.interactive,
                },
                animation::AnimationPlugin {
                    interactive: self.interactive,
                },
                objects::ObjectsPlugin {
                    interactive: self.interactive,
                },
            ));
    }
}

/// Opens the viewer window and runs until it closes (or the script ends).
pub fn run(options: ViewOptions) -> anyhow::Result<()> {
    let mut app = App::new();
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    app.add_plugins(
        DefaultPlugins
            .set(WindowPlugin {
                primary_window: Some(Window {
                    title: "Tracery".into(),
                    resolution: WindowResolution::new(options.window.x, options.window.y)
                        .with_scale_factor_override(1.0),
                    present_mode: PresentMode::AutoNoVsync,
                    ..default()
                }),
                ..default()
            })
            // The ray tracer has the cores (rayon); Bevy's own pools stay small so the two
            // do not fight over them.
            .set(TaskPoolPlugin {
                task_pool_options: TaskPoolOptions {
                    min_total_threads: 1,
                    max_total_threads: threads.min(3),
                    io: TaskPoolThreadAssignmentPolicy {
                        min_threads: 1,
                        max_threads: 1,
                        percent: 0.25,
                        on_thread_spawn: None,
                        on_thread_destroy: None,
                    },
                    async_compute: TaskPoolThreadAssignmentPolicy {
                        min_threads: 1,
                        max_threads: 1,
                        percent: 0.25,
                        on_thread_spawn: None,
                        on_thread_destroy: None,
                    },
                    compute: TaskPoolThreadAssignmentPolicy {
                        min_threads: 1,
                        max_threads: 1,
                        percent: 1.0,
                        on_thread_spawn: None,
                        on_thread_destroy: None,
                    },
                },
            }),
    )
    .add_plugins(EguiPlugin::default())
    .insert_resource(EguiGlobalSettings {
        auto_create_primary_context: false,
        ..default()
    })
    .insert_resource(ClearColor(Color::BLACK))
    .add_plugins(CorePlugins {
        scene: options.scene.clone(),
        bvh: options.bvh,
        settings: options.settings.clone(),
        viewport: options.window,
        interactive: true,
    })
    .add_plugins((
        display::DisplayPlugin,
        pacing::PacingPlugin,
        camera::FlyCameraPlugin,
        gizmos::BvhGizmoPlugin,
        inspector::InspectorPlugin {
            visible: options.inspector,
        },
        capture::CapturePlugin {
            script: options.script.clone(),
        },
        panel_cache::PanelCachePlugin,
    ))
    .insert_resource(options.leaves.clone())
    .insert_resource(animation::Timeline::starting(
        options.animation.0,
        options.animation.1,
    ))
    .insert_resource(StartState {
        gizmos: options.gizmos,
        ray: options.ray,
        look: options.look,
    })
    .add_systems(PostStartup, (egui_on_gizmo_camera, start_state))
    .add_systems(Update, start_pose.after(debug_ray::DebugRaySystems));
    match app.run() {
        AppExit::Success => Ok(()),
        AppExit::Error(code) => anyhow::bail!("the viewer exited with code {code}"),
    }
}

#[derive(Resource)]
struct StartState {
    gizmos: StartGizmos,
    ray: Option<Vec2>,
    look: Option<(Vec3, Vec3)>,
}

/// The inspector draws on the top camera (the one with the gizmos), over everything.
fn egui_on_gizmo_camera(mut commands: Commands, cams: Query<Entity, With<trace::TraceCamera>>) {
    for e in &cams {
        commands.entity(e).insert(PrimaryEguiContext);
    }
}

fn start_state(
    start: Res<StartState>,
    mut store: ResMut<GizmoConfigStore>,
    mut debug: ResMut<debug_ray::DebugRay>,
    mut shoot: MessageWriter<debug_ray::ShootRay>,
) {
    store.config_mut::<gizmos::BvhLevelGizmos>().0.enabled = start.gizmos.level;
    store.config_mut::<gizmos::LeafGizmos>().0.enabled = start.gizmos.leaves;
    debug.show_nodes = start.gizmos.ray_nodes;
    if let Some(p) = start.ray {
        shoot.write(debug_ray::ShootRay(p));
    }
}

/// Takes the `--look-from/--look-at` pose once the scene is loaded with its BVH and the start
/// ray (if any) has been shot through the scene's own camera.
fn start_pose(
    mut commands: Commands,
    mut start: ResMut<StartState>,
    current: Res<scene::CurrentScene>,
    loading: Res<scene::SceneLoading>,
    bvh: Res<bvh::SceneBvh>,
    debug: Res<debug_ray::DebugRay>,
    mut cameras: Query<(Entity, &mut Transform), With<camera::FlyCamera>>,
) {
    let Some((eye, target)) = start.look else {
        return;
    };
    let ready = loading.current().is_none()
        && bvh.for_scene(current.generation).is_some()
        && (start.ray.is_none() || debug.pixel.is_some());
    if !ready {
        return;
    }
    // Given in world coordinates; the scene is traced in its mesh's local frame.
    let o = current.scene.mesh.origin;
    let (eye, target) = (
        (eye.as_dvec3() - o).as_vec3(),
        (target.as_dvec3() - o).as_vec3(),
    );
    let forward = (target - eye).normalize_or_zero();
    let up = if forward.cross(Vec3::Y).length_squared() > 1e-6 {
        Vec3::Y
    } else {
        Vec3::Z
    };
    for (entity, mut t) in &mut cameras {
        *t = Transform::from_translation(eye).looking_at(target, up);
        // The free camera takes its yaw and pitch from the new transform.
        commands
            .entity(entity)
            .insert(bevy::camera_controller::free_camera::FreeCameraState::default());
    }
    start.look = None;
}
