//! Showing the traced image: a 2D camera draws it as a sprite stretched over the window, and
//! a 3D camera above it (no clear) carries the view used for the rays and draws the gizmos,
//! so lines land on the traced pixels. Files dropped on the window are opened.

use bevy::asset::RenderAssetUsages;
use bevy::camera::ClearColorConfig;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::image::{ImageFilterMode, ImageSampler};
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy::window::{FileDragAndDrop, PrimaryWindow};

use super::scene::LoadScene;
use super::trace::{TraceCamera, TraceSystems, TracedImage, ViewportSize};

/// The cameras, the sprite and the texture it shows.
pub struct DisplayPlugin;

impl Plugin for DisplayPlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(Startup, spawn_view)
            .add_systems(First, track_window_size)
            .add_systems(PreUpdate, open_dropped_files)
            .add_systems(Update, show_traced_image.after(TraceSystems));
    }
}

/// The texture the traced image is copied into.
#[derive(Resource)]
pub struct DisplayImage {
    /// Its handle.
    pub handle: Handle<Image>,
    shown: u64,
}

/// Marks the sprite that shows the traced image.
#[derive(Component)]
pub struct TracedSprite;

/// A black texture; a preview is filtered (it is stretched), the full image shown pixel for
/// pixel.
fn blank(width: u32, height: u32, preview: bool) -> Image {
    let mut image = Image::new_fill(
        Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        &[0, 0, 0, 255],
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD,
    );
    image.sampler = if preview {
        ImageSampler::linear()
    } else {
        ImageSampler::nearest()
    };
    image
}

fn spawn_view(mut commands: Commands, mut images: ResMut<Assets<Image>>) {
    let handle = images.add(blank(1, 1, true));
    commands.insert_resource(DisplayImage {
        handle: handle.clone(),
        shown: 0,
    });
    // The traced image is tone mapped and sRGB-encoded already: no tonemapping on either
    // camera, or Bevy's post-processing would shift its colours.
    commands.spawn((
        Camera2d,
        Camera {
            order: 0,
            ..default()
        },
        Tonemapping::None,
        // Multisampling would only smooth the gizmo lines, at four times the fill cost of
        // every pass (all on the CPU under a software Vulkan driver).
        Msaa::Off,
    ));
    commands.spawn((
        Sprite {
            image: handle,
            custom_size: Some(Vec2::ONE),
            ..default()
        },
        TracedSprite,
    ));
    commands.spawn((
        Camera3d::default(),
        Camera {
            order: 1,
            clear_color: ClearColorConfig::None,
            ..default()
        },
        Tonemapping::None,
        Msaa::Off,
        Projection::Perspective(PerspectiveProjection::default()),
        Transform::IDENTITY,
        TraceCamera,
        super::camera::FlyCamera,
    ));
}

fn track_window_size(
    window: Query<&Window, With<PrimaryWindow>>,
    mut viewport: ResMut<ViewportSize>,
    mut sprite: Query<&mut Sprite, With<TracedSprite>>,
) {
    let Ok(window) = window.single() else {
        return;
    };
    let physical = UVec2::new(window.physical_width(), window.physical_height()).max(UVec2::ONE);
    viewport.set_if_neq(ViewportSize(physical));
    for mut s in &mut sprite {
        let logical = Some(window.size());
        if s.custom_size != logical {
            s.custom_size = logical;
        }
    }
}

fn show_traced_image(
    mut traced: ResMut<TracedImage>,
    mut display: ResMut<DisplayImage>,
    mut images: ResMut<Assets<Image>>,
) {
    if traced.version == display.shown || traced.rgba.is_empty() {
        return;
    }
    let first = display.shown == 0;
    display.shown = traced.version;
    let Some(mut image) = images.get_mut(&display.handle) else {
        return;
    };
    let size = image.size();
    let filtered = matches!(image.sampler, ImageSampler::Descriptor(ref d) if d.mag_filter == ImageFilterMode::Linear);
    if first || size.x != traced.width || size.y != traced.height || filtered != traced.preview {
        *image = blank(traced.width, traced.height, traced.preview);
    }
    // The pixels move to the texture: the trace system writes a new buffer for the next image.
    image.data = Some(std::mem::take(&mut traced.rgba));
}

fn open_dropped_files(
    mut drops: MessageReader<FileDragAndDrop>,
    mut load: MessageWriter<LoadScene>,
) {
    for d in drops.read() {
        if let FileDragAndDrop::DroppedFile { path_buf, .. } = d {
            load.write(LoadScene(path_buf.clone()));
        }
    }
}
