//! Showing the traced image. The trace worker hands over pictures tone mapped and resized
//! to the window already; they are uploaded to a texture; a render system copies that texture into the 3D camera's main texture before
//! the camera draws, so the gizmos land on the traced pixels and no shader pass touches the
//! picture (under a software Vulkan driver each full-window pass costs milliseconds).
//! Files dropped on the window are opened.

use bevy::asset::RenderAssetUsages;
use bevy::camera::{CameraMainTextureUsages, ClearColorConfig, SubCameraView};
use bevy::core_pipeline::Core3dSystems;
use bevy::core_pipeline::schedule::Core3d;
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::extract_component::{ExtractComponent, ExtractComponentPlugin};
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat, TextureUsages};
use bevy::render::renderer::{RenderContext, ViewQuery};
use bevy::render::texture::GpuImage;
use bevy::render::view::ViewTarget;
use bevy::window::FileDragAndDrop;
use bevy::window::PrimaryWindow;

use super::PanelWidth;
use super::scene::LoadScene;
use super::trace::{TraceCamera, TraceSystems, TracedImage, ViewportSize};
use crate::render::resample::{Filter, resize_rgba8};

/// The camera, the texture the traced image is shown through, and the copy into the frame.
pub struct DisplayPlugin;

impl Plugin for DisplayPlugin {
    fn build(&self, app: &mut App) {
        app.add_plugins(ExtractComponentPlugin::<TracedBackground>::default())
            .add_systems(Startup, spawn_view)
            .add_systems(First, track_window_size)
            .add_systems(PreUpdate, open_dropped_files)
            .add_systems(
                Update,
                show_traced_image.in_set(ShowPicture).after(TraceSystems),
            );
        if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
            render_app.add_systems(Core3d, copy_background.before(Core3dSystems::Prepass));
        }
    }
}

/// The system that uploads a new picture (and takes its pixels): systems that read a picture's
/// pixels run before it.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub struct ShowPicture;

/// On a camera: the texture copied into its frame before it draws.
#[derive(Component, Clone, ExtractComponent)]
pub struct TracedBackground(pub Handle<Image>);

/// Which traced picture the display texture holds.
#[derive(Resource, Default)]
struct Shown {
    version: u64,
}

/// A black window-sized picture, uploaded to the GPU only (the main world keeps no copy).
fn blank(size: UVec2) -> Image {
    let mut image = Image::new_fill(
        Extent3d {
            width: size.x,
            height: size.y,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        &[0, 0, 0, 255],
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.usage =
        TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_DST | TextureUsages::COPY_SRC;
    image
}

fn spawn_view(mut commands: Commands, mut images: ResMut<Assets<Image>>, size: Res<ViewportSize>) {
    let handle = images.add(blank(size.0));
    commands.init_resource::<Shown>();
    // The traced image is tone mapped and sRGB-encoded already: no tonemapping, or Bevy's
    // post-processing would shift its colours. The copy covers the whole frame: no clear.
    commands.spawn((
        Camera3d::default(),
        Camera {
            clear_color: ClearColorConfig::None,
            ..default()
        },
        // Copied into (the traced picture, the kept inspector panel) and out of (the panel).
        CameraMainTextureUsages::default().with(TextureUsages::COPY_DST | TextureUsages::COPY_SRC),
        TracedBackground(handle),
        Tonemapping::None,
        DebandDither::Disabled,
        // Multisampling would only smooth the gizmo lines, at four times the fill cost of
        // every pass (all on the CPU under a software Vulkan driver).
        Msaa::Off,
        Projection::Perspective(PerspectiveProjection::default()),
        Transform::IDENTITY,
        TraceCamera,
        super::camera::FlyCamera,
    ));
}

/// The picture fills the window left of the inspector panel: the viewport is that area, and
/// the camera's projection frames the scene for it (an off-centre frustum over the whole
/// window, so gizmos drawn over the full frame land on the traced pixels).
fn track_window_size(
    window: Query<&Window, With<PrimaryWindow>>,
    panel: Res<PanelWidth>,
    mut viewport: ResMut<ViewportSize>,
    mut cameras: Query<&mut Camera, With<TracedBackground>>,
) {
    let Ok(window) = window.single() else {
        return;
    };
    let physical = UVec2::new(window.physical_width(), window.physical_height()).max(UVec2::ONE);
    // At least a quarter of the window stays for the picture.
    let width = physical
        .x
        .saturating_sub(panel.0)
        .max(physical.x / 4)
        .max(1);
    let visible = UVec2::new(width, physical.y);
    viewport.set_if_neq(ViewportSize(visible));
    let sub = (visible != physical).then_some(SubCameraView {
        full_size: visible,
        offset: Vec2::ZERO,
        size: physical,
    });
    for mut camera in &mut cameras {
        if camera.sub_camera_view != sub {
            camera.sub_camera_view = sub;
        }
    }
}

/// Hands the newest traced picture to the display texture (the worker made it display-sized;
/// a picture made before a window resize is stretched to the new size).
fn show_traced_image(
    mut traced: ResMut<TracedImage>,
    mut shown: ResMut<Shown>,
    viewport: Res<ViewportSize>,
    camera: Query<&TracedBackground>,
    mut images: ResMut<Assets<Image>>,
) {
    if traced.version == shown.version || traced.rgba.is_empty() {
        return;
    }
    let Ok(background) = camera.single() else {
        return;
    };
    let Some(mut image) = images.get_mut(&background.0) else {
        return;
    };
    shown.version = traced.version;
    let size = viewport.0;
    if image.size() != size {
        *image = blank(size);
    }
    // The pixels move on: the worker writes a new buffer for the next picture.
    let rgba = std::mem::take(&mut traced.rgba);
    image.data = Some(resize_rgba8(
        rgba,
        traced.width,
        traced.height,
        size.x,
        size.y,
        Filter::Nearest,
    ));
}

/// Copies the display texture into the camera's main texture (same size and format) before
/// anything is drawn into it.
fn copy_background(
    view: ViewQuery<(&ViewTarget, &TracedBackground)>,
    images: Res<RenderAssets<GpuImage>>,
    mut ctx: RenderContext,
) {
    let (target, background) = view.into_inner();
    let Some(image) = images.get(&background.0) else {
        return;
    };
    let main = target.main_texture();
    let (from, to) = (image.texture_descriptor.size, main.size());
    if image.texture_descriptor.format.remove_srgb_suffix()
        != target.main_texture_format().remove_srgb_suffix()
    {
        return;
    }
    // While a resize is under way the two differ for a frame: copy what overlaps.
    let size = Extent3d {
        width: from.width.min(to.width),
        height: from.height.min(to.height),
        depth_or_array_layers: 1,
    };
    ctx.command_encoder().copy_texture_to_texture(
        image.texture.as_image_copy(),
        main.as_image_copy(),
        size,
    );
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
