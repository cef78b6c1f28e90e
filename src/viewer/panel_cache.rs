//! The inspector drawn once, shown many times. Under a software Vulkan driver egui's pass is
//! about as costly as the rest of a frame's drawing (its shader converts every pixel to and
//! from sRGB, and the panel is blended over what is beneath it), yet from one frame to the
//! next the panel rarely changes. So when egui's output is the same as the last frame's,
//! egui draws nothing and the panel's pixels, kept from the frame that drew them, are copied
//! into the frame instead: a copy, no shader.
//!
//! The copy covers the rectangle around everything egui drew, so it is only used when that
//! rectangle lies beside the picture (the side panel): with a pop-up, a tooltip or the key
//! help over the picture, egui draws every frame as usual. `TRACERY_PANEL_CACHE=off` turns the
//! cache off (the window test compares the two).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use bevy::core_pipeline::schedule::Core3d;
use bevy::core_pipeline::upscaling::upscaling;
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::extract_resource::{ExtractResource, ExtractResourcePlugin};
use bevy::render::render_resource::{
    Extent3d, Origin3d, Texture, TextureDescriptor, TextureDimension, TextureUsages,
};
use bevy::render::renderer::{RenderContext, RenderDevice, ViewQuery};
use bevy::render::view::ViewTarget;
use bevy::window::PrimaryWindow;
use bevy_egui::{EguiOutput, EguiPostUpdateSet, EguiRenderOutput, egui};

use super::display::TracedBackground;
use super::trace::ViewportSize;

/// Keeps the inspector's pixels and reuses them while egui's output does not change.
pub struct PanelCachePlugin;

impl Plugin for PanelCachePlugin {
    fn build(&self, app: &mut App) {
        let stored = StoredGeneration::default();
        let enabled = std::env::var("TRACERY_PANEL_CACHE").map_or(true, |v| v != "off");
        app.insert_resource(PanelState {
            enabled,
            ..default()
        })
        .init_resource::<PanelCopy>()
        .init_resource::<PanelCounts>()
        .insert_resource(stored.clone())
        .add_plugins(ExtractResourcePlugin::<PanelCopy>::default())
        .add_systems(
            PostUpdate,
            decide_copy.after(EguiPostUpdateSet::ProcessOutput),
        );
        if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
            render_app
                .insert_resource(stored)
                .init_resource::<PanelTexture>()
                .add_systems(
                    Core3d,
                    copy_panel
                        .after(bevy_egui::render::egui_pass)
                        .before(upscaling),
                );
        }
    }
}

/// What the render world does with the panel this frame.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PanelCopy {
    /// Nothing: egui draws as usual (nothing drawn, or something over the picture).
    #[default]
    Off,
    /// Egui draws; afterwards its pixels inside `rect` are kept, as `generation`.
    Store {
        /// Physical pixels of the window, the panel and everything egui drew.
        rect: URect,
        /// Counts the stores, so the main world knows which one the render world has done.
        generation: u64,
    },
    /// Egui draws nothing; the kept pixels inside the rectangle are copied into the frame.
    Restore(URect),
}

impl ExtractResource for PanelCopy {
    type Source = PanelCopy;
    fn extract_resource(source: &Self::Source) -> Self {
        *source
    }
}

/// How often the panel was drawn by egui and how often its kept pixels were shown instead
/// (the `--orbit` report prints them).
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PanelCounts {
    /// Frames egui drew, kept afterwards.
    pub drawn: u64,
    /// Frames that showed the kept pixels.
    pub reused: u64,
    /// Frames egui drew with the cache out of use (something over the picture, or turned
    /// off).
    pub uncached: u64,
}

/// The last store the render world carried out (shared by both worlds: the render world runs
/// a frame behind the main world, and may skip a frame, e.g. while the window is minimized).
#[derive(Resource, Clone, Default)]
struct StoredGeneration(Arc<AtomicU64>);

/// The main world's side: the last drawn output and which store holds it.
#[derive(Resource, Default)]
struct PanelState {
    enabled: bool,
    last: Vec<egui::ClippedPrimitive>,
    /// The first store of the current output: its generation, rectangle and window size.
    kept: Option<(u64, URect, UVec2)>,
    generation: u64,
}

/// The rectangle, in physical pixels, around everything `jobs` draw (each primitive's vertices
/// within its clip rectangle), clamped to the window; `None` if nothing is drawn.
pub fn drawn_rect(
    jobs: &[egui::ClippedPrimitive],
    pixels_per_point: f32,
    window: UVec2,
) -> Option<URect> {
    let mut area = egui::Rect::NOTHING;
    for job in jobs {
        let clip = job.clip_rect;
        let bounds = match &job.primitive {
            egui::epaint::Primitive::Mesh(mesh) => mesh.calc_bounds(),
            egui::epaint::Primitive::Callback(c) => c.rect,
        };
        let r = bounds.intersect(clip);
        if r.is_positive() {
            area = area.union(r);
        }
    }
    if !area.is_positive() {
        return None;
    }
    let scale = |v: f32| v * pixels_per_point;
    let min = UVec2::new(
        scale(area.min.x).floor().max(0.0) as u32,
        scale(area.min.y).floor().max(0.0) as u32,
    );
    let max = UVec2::new(
        (scale(area.max.x).ceil().max(0.0) as u32).min(window.x),
        (scale(area.max.y).ceil().max(0.0) as u32).min(window.y),
    );
    (min.x < max.x && min.y < max.y).then_some(URect::from_corners(min, max))
}

/// Whether two frames' egui output draws the same: the same meshes, clip rectangles and
/// textures (paint callbacks never count as the same).
pub fn same_output(a: &[egui::ClippedPrimitive], b: &[egui::ClippedPrimitive]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            x.clip_rect == y.clip_rect
                && match (&x.primitive, &y.primitive) {
                    (egui::epaint::Primitive::Mesh(m), egui::epaint::Primitive::Mesh(n)) => m == n,
                    _ => false,
                }
        })
}

/// Whether the output can be kept: it draws only beside the picture (one pixel of the panel's
/// anti-aliased edge may fall on the picture's last column) and has no paint callbacks.
fn keepable(jobs: &[egui::ClippedPrimitive], rect: URect, picture_width: u32) -> bool {
    rect.min.x + 1 >= picture_width
        && jobs
            .iter()
            .all(|j| matches!(j.primitive, egui::epaint::Primitive::Mesh(_)))
}

/// This frame's copy, given the output egui made (`rect`: what it draws, from [`drawn_rect`])
/// and the last store the render world carried out; updates what is kept.
fn decide(
    state: &mut PanelState,
    jobs: &[egui::ClippedPrimitive],
    textures_changed: bool,
    rect: Option<URect>,
    window: UVec2,
    picture_width: u32,
    stored: u64,
) -> PanelCopy {
    let Some(rect) = rect.filter(|r| state.enabled && keepable(jobs, *r, picture_width)) else {
        state.kept = None;
        return PanelCopy::Off;
    };
    let same = !textures_changed
        && state.kept.is_some_and(|(_, r, s)| r == rect && s == window)
        && same_output(&state.last, jobs);
    if let (true, Some((first, _, _))) = (same, state.kept)
        && stored >= first
    {
        return PanelCopy::Restore(rect);
    }
    // Drawn by egui and kept: new output, or the same whose store the render world has not
    // carried out yet (it runs a frame behind).
    state.generation += 1;
    let generation = state.generation;
    if !same {
        state.kept = Some((generation, rect, window));
        state.last = jobs.to_vec();
    }
    PanelCopy::Store { rect, generation }
}

fn decide_copy(
    mut outputs: Query<(&mut EguiRenderOutput, &EguiOutput)>,
    window: Query<&Window, With<PrimaryWindow>>,
    viewport: Res<ViewportSize>,
    stored: Res<StoredGeneration>,
    mut state: ResMut<PanelState>,
    mut copy: ResMut<PanelCopy>,
    mut counts: ResMut<PanelCounts>,
) {
    let (Ok((mut render, output)), Ok(window)) = (outputs.single_mut(), window.single()) else {
        *copy = PanelCopy::Off;
        return;
    };
    let size = UVec2::new(window.physical_width(), window.physical_height());
    let rect = drawn_rect(&render.paint_jobs, output.pixels_per_point, size);
    *copy = decide(
        &mut state,
        &render.paint_jobs,
        !render.textures_delta.is_empty(),
        rect,
        size,
        viewport.0.x,
        stored.0.load(Ordering::Acquire),
    );
    match *copy {
        PanelCopy::Restore(_) => {
            // Egui draws nothing this frame; its texture updates still go through.
            render.paint_jobs.clear();
            counts.reused += 1;
        }
        PanelCopy::Store { .. } => counts.drawn += 1,
        PanelCopy::Off if rect.is_some() => counts.uncached += 1,
        PanelCopy::Off => {}
    }
}

/// The render world's copy of the kept panel pixels.
#[derive(Resource, Default)]
struct PanelTexture(Option<Texture>);

fn copy_panel(
    view: ViewQuery<(&ViewTarget, &TracedBackground)>,
    copy: Option<Res<PanelCopy>>,
    stored: Res<StoredGeneration>,
    device: Res<RenderDevice>,
    mut kept: ResMut<PanelTexture>,
    mut ctx: RenderContext,
) {
    let Some(copy) = copy.map(|c| *c) else {
        return;
    };
    let (target, _) = view.into_inner();
    let main = target.main_texture();
    let size = main.size();
    let format = target.main_texture_format();
    let clamp = |r: URect| {
        let max = r.max.min(UVec2::new(size.width, size.height));
        (r.min.x < max.x && r.min.y < max.y).then_some((r.min, max - r.min))
    };
    let fits = |t: &Texture| t.size() == size && t.format() == format;
    match copy {
        PanelCopy::Off => {}
        PanelCopy::Store { rect, generation } => {
            let Some((origin, extent)) = clamp(rect) else {
                return;
            };
            if !kept.0.as_ref().is_some_and(fits) {
                kept.0 = Some(device.create_texture(&TextureDescriptor {
                    label: Some("inspector panel"),
                    size,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: TextureDimension::D2,
                    format,
                    usage: TextureUsages::COPY_SRC | TextureUsages::COPY_DST,
                    view_formats: &[],
                }));
            }
            let texture = kept.0.as_ref().expect("created above");
            copy_rect(&mut ctx, main, texture, origin, extent);
            stored.0.store(generation, Ordering::Release);
        }
        PanelCopy::Restore(rect) => {
            // The main texture mostly still holds last frame's panel, but nothing promises it
            // (a new texture after a resize, gizmo lines drawn under the panel): the copy does.
            let (Some((origin, extent)), Some(texture)) = (clamp(rect), kept.0.as_ref()) else {
                return;
            };
            if fits(texture) {
                copy_rect(&mut ctx, texture, main, origin, extent);
            }
        }
    }
}

fn copy_rect(ctx: &mut RenderContext, from: &Texture, to: &Texture, origin: UVec2, extent: UVec2) {
    let at = Origin3d {
        x: origin.x,
        y: origin.y,
        z: 0,
    };
    let mut src = from.as_image_copy();
    src.origin = at;
    let mut dst = to.as_image_copy();
    dst.origin = at;
    ctx.command_encoder().copy_texture_to_texture(
        src,
        dst,
        Extent3d {
            width: extent.x,
            height: extent.y,
            depth_or_array_layers: 1,
        },
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use egui::epaint::{ClippedPrimitive, Mesh, Primitive};
    use egui::{Color32, Pos2, Rect};

    fn quad(x0: f32, y0: f32, x1: f32, y1: f32, colour: Color32) -> ClippedPrimitive {
        let mut mesh = Mesh::default();
        mesh.add_colored_rect(
            Rect::from_min_max(Pos2::new(x0, y0), Pos2::new(x1, y1)),
            colour,
        );
        ClippedPrimitive {
            clip_rect: Rect::EVERYTHING,
            primitive: Primitive::Mesh(mesh),
        }
    }

    #[test]
    fn the_drawn_rectangle_is_in_physical_pixels_rounded_outwards() {
        let window = UVec2::new(1280, 720);
        let jobs = [
            quad(950.5, 0.0, 1280.0, 720.0, Color32::GRAY),
            quad(960.0, 10.0, 1000.2, 20.0, Color32::WHITE),
        ];
        assert_eq!(
            drawn_rect(&jobs, 1.0, window),
            Some(URect::new(950, 0, 1280, 720))
        );
        // Two physical pixels a point.
        let small = [quad(100.25, 10.0, 200.0, 20.1, Color32::WHITE)];
        assert_eq!(
            drawn_rect(&small, 2.0, window),
            Some(URect::new(200, 20, 400, 41))
        );
        // Clipped, and clamped to the window.
        let mut clipped = quad(0.0, 0.0, 2000.0, 2000.0, Color32::WHITE);
        clipped.clip_rect = Rect::from_min_max(Pos2::new(1000.0, 5.0), Pos2::new(3000.0, 50.0));
        assert_eq!(
            drawn_rect(&[clipped], 1.0, window),
            Some(URect::new(1000, 5, 1280, 50))
        );
        assert_eq!(drawn_rect(&[], 1.0, window), None);
    }

    #[test]
    fn outputs_are_the_same_only_when_they_draw_the_same() {
        let a = vec![
            quad(950.0, 0.0, 1280.0, 720.0, Color32::GRAY),
            quad(960.0, 10.0, 1000.0, 20.0, Color32::WHITE),
        ];
        assert!(same_output(&a, &a.clone()));
        let mut b = a.clone();
        b[1] = quad(960.0, 10.0, 1000.0, 20.0, Color32::RED);
        assert!(!same_output(&a, &b));
        let mut c = a.clone();
        c[0].clip_rect = Rect::from_min_max(Pos2::ZERO, Pos2::new(10.0, 10.0));
        assert!(!same_output(&a, &c));
        assert!(!same_output(&a, &a[..1]));
    }

    #[test]
    fn kept_pixels_are_shown_only_once_stored_and_while_unchanged() {
        let window = UVec2::new(1280, 720);
        let mut state = PanelState {
            enabled: true,
            ..default()
        };
        let panel = vec![quad(950.0, 0.0, 1280.0, 720.0, Color32::GRAY)];
        let rect = drawn_rect(&panel, 1.0, window);
        let r = rect.unwrap();
        let step = |state: &mut PanelState, jobs: &[ClippedPrimitive], stored: u64| {
            decide(
                state,
                jobs,
                false,
                drawn_rect(jobs, 1.0, window),
                window,
                950,
                stored,
            )
        };
        // New output: drawn and stored.
        assert_eq!(
            step(&mut state, &panel, 0),
            PanelCopy::Store {
                rect: r,
                generation: 1
            }
        );
        // The same, but the render world has not stored it yet: drawn again.
        assert_eq!(
            step(&mut state, &panel, 0),
            PanelCopy::Store {
                rect: r,
                generation: 2
            }
        );
        // Stored (either store holds this output): reused.
        assert_eq!(step(&mut state, &panel, 1), PanelCopy::Restore(r));
        assert_eq!(step(&mut state, &panel, 2), PanelCopy::Restore(r));
        // Changed: drawn; its older stores do not count.
        let changed = vec![quad(950.0, 0.0, 1280.0, 720.0, Color32::DARK_GRAY)];
        assert_eq!(
            step(&mut state, &changed, 2),
            PanelCopy::Store {
                rect: r,
                generation: 3
            }
        );
        assert!(matches!(
            step(&mut state, &changed, 2),
            PanelCopy::Store { .. }
        ));
        assert_eq!(step(&mut state, &changed, 3), PanelCopy::Restore(r));
        // A new texture (egui's font atlas grew): drawn.
        assert!(matches!(
            decide(&mut state, &changed, true, rect, window, 950, 9),
            PanelCopy::Store { .. }
        ));
        // Something over the picture: egui draws as usual, and nothing kept is trusted after.
        let mut popup = changed.clone();
        popup.push(quad(600.0, 100.0, 960.0, 200.0, Color32::BLACK));
        assert_eq!(step(&mut state, &popup, 9), PanelCopy::Off);
        assert!(matches!(
            step(&mut state, &changed, 9),
            PanelCopy::Store { .. }
        ));
        // The window resized: drawn.
        assert!(matches!(
            decide(
                &mut state,
                &changed,
                false,
                rect,
                UVec2::new(1281, 720),
                950,
                99
            ),
            PanelCopy::Store { .. }
        ));
        // Turned off: never kept.
        let mut off = PanelState::default();
        assert_eq!(step(&mut off, &panel, 0), PanelCopy::Off);
    }
}
