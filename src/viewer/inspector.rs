//! The inspector (egui): scene, render settings, depth of field, environment, BVH settings and
//! statistics, gizmo and debug toggles, the heatmap legend and a button that saves the image;
//! a status line; F1 shows the keys.

use std::path::PathBuf;

use bevy::prelude::*;
use bevy_egui::input::EguiWantsInput;
use bevy_egui::{EguiContexts, EguiPrimaryContextPass, egui};

use super::animation::Timeline;
use super::bvh::{BvhBuilding, BvhSettings, SceneBvh};
use super::capture::SavePng;
use super::debug_ray::{DebugRay, DebugRayGizmos, FocusPicking};
use super::gizmos::{BvhIndex, BvhLevelGizmos, LeafGizmos, LeafView};
use super::objects::{SceneObject, Selection};
use super::scene::{CurrentScene, LoadScene, SceneLoading, ViewerStatus, scene_files};
use super::trace::{EXTERNAL, EnvChoice, RenderMode, TraceStats, ViewSettings};
use super::{PanelWidth, UiFocus};
use crate::bvh::SplitMethod;
use crate::render::cache::MovingFilter;
use crate::render::debug::ShadowState;
use crate::render::heatmap::heat_color;
use crate::sampling::SamplerKind;
use crate::scene::Integrator;
use crate::scene::Place;

/// The inspector window, the status line and the key help.
pub struct InspectorPlugin {
    /// Show the inspector at start (Tab toggles it).
    pub visible: bool,
}

impl Plugin for InspectorPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<StatusLine>()
            .insert_resource(InspectorState {
                visible: self.visible,
                help: false,
                scenes: scene_files(std::path::Path::new("assets/scenes")),
                hdrs: hdr_files(),
            })
            .add_systems(PreUpdate, track_focus)
            .add_systems(Update, keys)
            .add_systems(
                EguiPrimaryContextPass,
                (plain_style, status_line, inspector, help).chain(),
            );
    }
}

/// Drops the soft shadows under windows and pop-ups once: under a software Vulkan driver
/// their wide blended borders cost about 3 ms a frame.
fn plain_style(mut contexts: EguiContexts, mut done: Local<bool>) -> Result {
    if !*done {
        contexts.ctx_mut()?.global_style_mut(|style| {
            style.visuals.window_shadow = egui::Shadow::NONE;
            style.visuals.popup_shadow = egui::Shadow::NONE;
        });
        *done = true;
    }
    Ok(())
}

/// What the inspector shows.
#[derive(Resource)]
pub struct InspectorState {
    /// The inspector window is open (Tab).
    pub visible: bool,
    /// The key help is open (F1).
    pub help: bool,
    scenes: Vec<PathBuf>,
    hdrs: Vec<PathBuf>,
}

fn hdr_files() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(std::path::Path::new(EXTERNAL).join("hdr"))
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "exr" || x == "hdr"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// The keys, as F1 lists them.
pub const KEYS: &[(&str, &str)] = &[
    ("W A S D", "fly forward, left, back, right"),
    ("E / Q", "fly up / down"),
    ("Shift", "fly faster"),
    ("Right mouse (hold) / M", "look around / toggle mouse look"),
    ("Scroll", "change flying speed"),
    (
        "Left click",
        "shoot a debug ray through the pixel; pick the object there",
    ),
    ("F, then click", "focus the lens on the clicked point"),
    ("B", "BVH boxes of one level"),
    ("[ / ]", "level down / up"),
    ("O", "overlap view of the level"),
    ("L", "BVH leaves"),
    (", / .", "previous / next leaf"),
    ("R", "debug ray drawing"),
    ("H", "traversal cost heatmap"),
    ("G", "where the samples go (work heatmap)"),
    ("N", "denoise the still picture on / off"),
    ("Space", "play / pause the animation"),
    ("Arrows, Page Up / Down", "move the picked object"),
    ("Z / X, - / =", "turn / scale the picked object"),
    ("Esc", "let the picked object go"),
    ("P", "save the full-resolution image as PNG"),
    ("Tab", "show / hide the inspector"),
    ("F1", "this help"),
];

fn track_focus(wants: Option<Res<EguiWantsInput>>, mut focus: ResMut<UiFocus>) {
    let Some(w) = wants else {
        return;
    };
    let now = UiFocus {
        pointer: w.wants_any_pointer_input(),
        keyboard: w.wants_any_keyboard_input(),
    };
    focus.set_if_neq(now);
}

fn keys(
    input: Res<ButtonInput<KeyCode>>,
    focus: Res<UiFocus>,
    mut state: ResMut<InspectorState>,
    mut save: MessageWriter<SavePng>,
    mut settings: ResMut<ViewSettings>,
) {
    if focus.keyboard {
        return;
    }
    if input.just_pressed(KeyCode::KeyN) && crate::denoise::AVAILABLE {
        settings.denoise = !settings.denoise;
    }
    if input.just_pressed(KeyCode::F1) {
        state.help = !state.help;
    }
    if input.just_pressed(KeyCode::Tab) {
        state.visible = !state.visible;
    }
    if input.just_pressed(KeyCode::KeyP) {
        save.write(SavePng(None));
    }
}

/// The status line's text as the top of the inspector shows it.
#[derive(Resource, Default)]
struct StatusLine {
    text: String,
    /// What the text says apart from its figures (scene, moving or still, loading, building,
    /// waiting): when that changes, the line is rewritten at once.
    kind: String,
    shown: Option<std::time::Instant>,
}

/// How often the status line's figures are rewritten: a panel that changes every frame is
/// drawn every frame (`panel_cache`), and figures that change 30 times a second cannot be
/// read anyway.
const STATUS_REFRESH: std::time::Duration = std::time::Duration::from_millis(250);

#[allow(clippy::too_many_arguments)]
fn status_line(
    stats: Res<TraceStats>,
    bvh: Res<SceneBvh>,
    building: Res<BvhBuilding>,
    loading: Res<SceneLoading>,
    current: Res<CurrentScene>,
    time: Res<Time<Real>>,
    state: Res<InspectorState>,
    mut line: ResMut<StatusLine>,
) {
    if !state.visible {
        return;
    }
    let frame_ms = time.delta_secs_f64() * 1e3;
    // Idle, the window redraws only on events: the time since the last one is no frame time.
    let frame = if stats.idle && frame_ms > 250.0 {
        "frame: idle".to_string()
    } else {
        format!("frame {frame_ms:.1} ms")
    };
    let picture = if stats.moving {
        format!("moving, {} fresh samples", stats.fresh)
    } else {
        let denoised = if stats.denoised { ", denoised" } else { "" };
        let done = if stats.idle { ", done" } else { "" };
        format!("{} spp{denoised}{done}", stats.spp)
    };
    let mut text = format!(
        "{}\n{picture}\n{:.1} Mrays/s | {frame}\nBVH {:.1} ms | {}x{}",
        current.scene.name,
        stats.mrays_per_s,
        bvh.bvh.as_ref().map_or(0.0, |b| b.stats.build_ms),
        stats.size.x,
        stats.size.y,
    );
    let loading = loading.current();
    let built = building.elapsed();
    if let Some((path, secs)) = &loading {
        text += &format!("\nloading {} ({secs:.1} s)", path.display());
    }
    if let Some(secs) = built {
        text += &format!("\nbuilding BVH ({secs:.1} s)");
    }
    if let Some(w) = stats.waiting {
        text += &format!("\n{w}");
    }
    let kind = format!(
        "{} {} {} {} {} {:?}",
        current.scene.name,
        stats.moving,
        stats.idle,
        loading.is_some(),
        built.is_some(),
        stats.waiting
    );
    let now = time.last_update().unwrap_or_else(std::time::Instant::now);
    let due = line
        .shown
        .is_none_or(|t| now.saturating_duration_since(t) >= STATUS_REFRESH);
    if due || kind != line.kind {
        line.text = text;
        line.kind = kind;
        line.shown = Some(now);
    }
}

fn help(mut contexts: EguiContexts, mut state: ResMut<InspectorState>) -> Result {
    if !state.help {
        return Ok(());
    }
    let ctx = contexts.ctx_mut()?;
    let mut open = true;
    egui::Window::new("Keys (F1)")
        .open(&mut open)
        .anchor(egui::Align2::CENTER_CENTER, egui::Vec2::ZERO)
        .collapsible(false)
        .show(ctx, |ui| {
            egui::Grid::new("keys").striped(true).show(ui, |ui| {
                for (k, what) in KEYS {
                    ui.label(egui::RichText::new(*k).strong());
                    ui.label(*what);
                    ui.end_row();
                }
            });
        });
    if !open {
        state.help = false;
    }
    Ok(())
}

/// The scene's objects as the inspector reads them.
type Objects<'w, 's> = Query<'w, 's, (&'static SceneObject, &'static Name, &'static Transform)>;

/// The inspector's panel width, status line, timeline, and the picked object.
type Panel<'w, 's> = (
    ResMut<'w, PanelWidth>,
    Res<'w, StatusLine>,
    ResMut<'w, Timeline>,
    (Res<'w, Selection>, Objects<'w, 's>),
);

/// Width of the inspector panel in logical pixels.
const INSPECTOR_WIDTH: f32 = 330.0;

#[allow(clippy::too_many_arguments)]
fn inspector(
    mut contexts: EguiContexts,
    state: Res<InspectorState>,
    current: Res<CurrentScene>,
    status: Res<ViewerStatus>,
    mut settings: ResMut<ViewSettings>,
    mut bvh_settings: ResMut<BvhSettings>,
    bvh: Res<SceneBvh>,
    building: Res<BvhBuilding>,
    index: Res<BvhIndex>,
    mut leaves: ResMut<LeafView>,
    mut store: ResMut<GizmoConfigStore>,
    mut debug: ResMut<DebugRay>,
    mut picking: ResMut<FocusPicking>,
    stats: Res<TraceStats>,
    (mut load, mut save): (MessageWriter<LoadScene>, MessageWriter<SavePng>),
    (mut panel, line, mut timeline, (selection, objects)): Panel,
) -> Result {
    if !state.visible {
        panel.set_if_neq(PanelWidth(0));
        return Ok(());
    }
    let ctx = contexts.ctx_mut()?;
    // Edit copies, and write back only real changes, so change detection (which resets the
    // accumulation and rebuilds the BVH) fires exactly when a value changes.
    let mut s = settings.clone();
    let mut b = bvh_settings.0;
    // A side panel: the picture fills the rest of the window (the display and the trace
    // camera read its width), so nothing of the scene is under it. (bevy_egui hands out a
    // context, not a root `Ui`, so the panel is shown at the top level.)
    #[allow(deprecated)]
    let shown = egui::Panel::right("inspector")
        .resizable(false)
        .exact_size(INSPECTOR_WIDTH)
        .show(ctx, |ui| {
            // The status line heads the panel, outside the scrolling part: nothing of the
            // picture is under it.
            ui.add(egui::Label::new(egui::RichText::new(&line.text).monospace()).wrap());
            ui.separator();
            egui::ScrollArea::vertical().show(ui, |ui| {
                ui.heading("Inspector");
                scene_section(ui, &state, &current, &status, &mut load);
                if let Some(t) = super::animation::section(ui, &timeline, &current) {
                    *timeline = t;
                }
                object_section(ui, &current, &selection, &objects);
                render_section(ui, &mut s, &stats, current.scene.integrator);
                dof_section(ui, &mut s, &mut picking.0);
                env_section(ui, &mut s, &state);
                bvh_section(ui, &mut b, &bvh, &building);
                gizmo_section(ui, &mut s, &index, &mut leaves, &mut store, &mut debug);
                ui.separator();
                if ui.button("Save full-resolution PNG (P)").clicked() {
                    save.write(SavePng(None));
                }
                if let Some(n) = &status.notice {
                    ui.label(n);
                }
            });
        });
    // From the panel's left edge to the window's right (the panel's frame included).
    let width = ((ctx.content_rect().right() - shown.response.rect.left()).max(0.0)
        * ctx.pixels_per_point())
    .round() as u32;
    panel.set_if_neq(PanelWidth(width));
    if s != *settings {
        *settings = s;
    }
    if b != bvh_settings.0 {
        bvh_settings.0 = b;
    }
    Ok(())
}

/// The scene's objects (how many; how many of them are placements of meshes held once) and
/// the picked one: its name, triangles and where it stands.
fn object_section(
    ui: &mut egui::Ui,
    current: &CurrentScene,
    selection: &Selection,
    objects: &Objects,
) {
    let scene = &current.scene;
    if scene.objects.is_empty() {
        return;
    }
    egui::CollapsingHeader::new("Objects")
        .default_open(true)
        .show(ui, |ui| {
            let placed = &scene.instances;
            if placed.is_empty() {
                ui.label(format!(
                    "{} objects (click one to pick it)",
                    scene.objects.len()
                ));
            } else {
                ui.label(format!(
                    "{} objects, {} of them placements of {} meshes (click one to pick it)",
                    scene.objects.len(),
                    placed.placements().len(),
                    placed.meshes.len()
                ));
            }
            let Some((o, name, t)) = selection.0.and_then(|e| objects.get(e).ok()) else {
                return;
            };
            ui.label(egui::RichText::new(name.as_str()).strong());
            let how = match scene.objects.get(o.object).map(|x| x.place) {
                Some(Place::Placed(p)) => placed.placements().get(p).map_or(String::new(), |p| {
                    format!(" (a placement of mesh {})", p.mesh)
                }),
                _ => " (of the scene's own: moving it lifts it into a mesh of its own)".into(),
            };
            ui.label(format!("{} triangles{how}", o.triangles));
            let p = t.translation;
            ui.label(format!("at ({:.3}, {:.3}, {:.3})", p.x, p.y, p.z));
            ui.label("arrows, Page Up / Down: move; Z / X: turn; - / =: scale; Esc: let go");
        });
}

fn scene_section(
    ui: &mut egui::Ui,
    state: &InspectorState,
    current: &CurrentScene,
    status: &ViewerStatus,
    load: &mut MessageWriter<LoadScene>,
) {
    egui::CollapsingHeader::new("Scene")
        .default_open(true)
        .show(ui, |ui| {
            ui.label(format!(
                "{}: {} triangles, {} lights",
                current.scene.name,
                current.scene.triangle_count(),
                current.scene.lights.len()
            ));
            let selected = current
                .source
                .as_ref()
                .map_or("Cornell box (built in)".to_string(), |p| {
                    p.display().to_string()
                });
            egui::ComboBox::from_id_salt("scene")
                .selected_text(selected)
                .width(260.0)
                .show_ui(ui, |ui| {
                    for p in &state.scenes {
                        let name = p.file_stem().unwrap_or_default().to_string_lossy();
                        if ui
                            .selectable_label(current.source.as_ref() == Some(p), name)
                            .clicked()
                        {
                            load.write(LoadScene(p.clone()));
                        }
                    }
                });
            ui.small("Drop an OBJ, PLY, glTF or scene file on the window to open it.");
            if let Some(e) = &status.error {
                ui.colored_label(egui::Color32::from_rgb(255, 110, 90), e);
            }
        });
}

fn render_section(
    ui: &mut egui::Ui,
    s: &mut ViewSettings,
    stats: &TraceStats,
    scene_integrator: Integrator,
) {
    egui::CollapsingHeader::new("Render")
        .default_open(true)
        .show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.radio_value(&mut s.mode, RenderMode::Shaded, "Shaded");
                ui.radio_value(&mut s.mode, RenderMode::TraversalCost, "Cost (H)");
                ui.radio_value(&mut s.mode, RenderMode::Overlap, "Overlap (O)");
                ui.radio_value(&mut s.mode, RenderMode::Work, "Work (G)");
            })
            .response
            .on_hover_text(
                "Work: samples per pixel each 16x16 tile took for the last picture \
                 (while moving, changed and noisy tiles get more)",
            );
            ui.add(egui::Slider::new(&mut s.scale, 0.1..=1.0).text("resolution scale"));
            ui.add(
                egui::Slider::new(&mut s.max_samples, 1..=4096)
                    .logarithmic(true)
                    .text("max samples per pixel"),
            );
            egui::ComboBox::from_label("integrator")
                .selected_text(match s.integrator {
                    None => format!("scene's ({scene_integrator})"),
                    Some(i) => i.to_string(),
                })
                .show_ui(ui, |ui| {
                    ui.selectable_value(
                        &mut s.integrator,
                        None,
                        format!("scene's ({scene_integrator})"),
                    );
                    ui.selectable_value(&mut s.integrator, Some(Integrator::Direct), "direct")
                        .on_hover_text(
                            "light from the lights and emissive surfaces only, no bounces",
                        );
                    ui.selectable_value(&mut s.integrator, Some(Integrator::Path), "path")
                        .on_hover_text("global illumination: diffuse bounces, colour bleeding");
                });
            ui.add(egui::Slider::new(&mut s.max_depth, 0..=16).text("bounce depth"));
            ui.checkbox(&mut s.shadows, "shadows");
            ui.add_enabled(
                s.shadows,
                egui::Checkbox::new(&mut s.transparent_shadows, "transparent shadows"),
            );
            ui.checkbox(&mut s.normal_maps, "normal maps")
                .on_hover_text(
                    "materials' normal and height (bump) maps bend the shading normal (off: the mesh's own normals)",
                );
            ui.add_enabled(
                s.normal_maps,
                egui::Checkbox::new(&mut s.soft_terminator, "soft terminator"),
            )
            .on_hover_text(
                "a shadowing term for the normals the maps bend, which softens their hard shadow edge (as Mitsuba 3 does)",
            );
            egui::ComboBox::from_label("sampler")
                .selected_text(s.sampler.to_string())
                .show_ui(ui, |ui| {
                    ui.selectable_value(&mut s.sampler, SamplerKind::Sobol, "sobol");
                    ui.selectable_value(&mut s.sampler, SamplerKind::Random, "random");
                });
            ui.add(
                egui::Slider::new(&mut s.exposure, 0.05..=8.0)
                    .logarithmic(true)
                    .text("exposure"),
            );
            ui.add(
                egui::Slider::new(&mut s.frame_ms, 0.0..=100.0).text("ms per frame (0: fastest)"),
            );
            ui.add(
                egui::Slider::new(&mut s.moving_budget_ms, 1.0..=100.0)
                    .text("ms per moving picture"),
            );
            ui.add(
                egui::Slider::new(&mut s.still_after_ms, 0.0..=1000.0)
                    .text("ms still before refining"),
            );
            egui::ComboBox::from_label("moving picture filter")
                .selected_text(s.moving_filter.name())
                .show_ui(ui, |ui| {
                    for f in MovingFilter::ALL {
                        ui.selectable_value(&mut s.moving_filter, f, f.name());
                    }
                });
            let denoise = ui.add_enabled(
                crate::denoise::AVAILABLE && stats.denoise_error.is_none(),
                egui::Checkbox::new(&mut s.denoise, "denoise the still picture (N)"),
            );
            if !crate::denoise::AVAILABLE {
                denoise.on_disabled_hover_text(crate::denoise::NOT_BUILT);
            } else if let Some(e) = &stats.denoise_error {
                denoise.on_disabled_hover_text(e.as_str());
            }
            if s.mode != RenderMode::Shaded {
                heat_legend(ui, s, stats);
            }
        });
}

fn heat_legend(ui: &mut egui::Ui, s: &mut ViewSettings, stats: &TraceStats) {
    let what = match s.mode {
        RenderMode::TraversalCost => "BVH nodes entered per camera ray",
        RenderMode::Work => "samples per pixel of each tile in the last picture",
        _ => "boxes of the level each camera ray crosses",
    };
    ui.label(what);
    let (rect, _) = ui.allocate_exact_size(egui::vec2(260.0, 16.0), egui::Sense::hover());
    let steps = 64;
    for i in 0..steps {
        let t = i as f32 / (steps - 1) as f32;
        let [r, g, b] = heat_color(t);
        let x0 = rect.left() + rect.width() * i as f32 / steps as f32;
        let x1 = rect.left() + rect.width() * (i + 1) as f32 / steps as f32;
        ui.painter().rect_filled(
            egui::Rect::from_min_max(
                egui::pos2(x0, rect.top()),
                egui::pos2(x1 + 0.5, rect.bottom()),
            ),
            0.0,
            egui::Color32::from_rgb(r, g, b),
        );
    }
    let (mean, top) = stats.heat;
    ui.horizontal(|ui| {
        ui.label("0");
        ui.add_space(200.0);
        ui.label(format!("{top:.2}"));
    });
    ui.label(format!("mean {mean:.2}, scale top {top:.2}"));
    ui.add(egui::Slider::new(&mut s.heat_max, 0.0..=512.0).text("scale top (0: auto)"));
}

fn dof_section(ui: &mut egui::Ui, s: &mut ViewSettings, picking: &mut bool) {
    egui::CollapsingHeader::new("Depth of field")
        .default_open(false)
        .show(ui, |ui| {
            ui.checkbox(&mut s.depth_of_field, "thin lens");
            ui.add(
                egui::DragValue::new(&mut s.focus_distance)
                    .speed(0.01)
                    .range(1e-4..=1e6)
                    .prefix("focus distance "),
            );
            ui.add(
                egui::DragValue::new(&mut s.lens_radius)
                    .speed(0.001)
                    .range(0.0..=1e4)
                    .prefix("lens radius "),
            );
            ui.add(
                egui::Slider::new(&mut s.max_samples, 1..=4096)
                    .logarithmic(true)
                    .text("samples per pixel"),
            );
            let label = if *picking {
                "Click the image to focus..."
            } else {
                "Focus on a clicked point (F)"
            };
            if ui.button(label).clicked() {
                *picking = !*picking;
            }
        });
}

fn env_section(ui: &mut egui::Ui, s: &mut ViewSettings, state: &InspectorState) {
    egui::CollapsingHeader::new("Environment")
        .default_open(false)
        .show(ui, |ui| {
            let name = |c: &EnvChoice| match c {
                EnvChoice::FromScene => "as the scene says".to_string(),
                EnvChoice::None => "none".into(),
                EnvChoice::Sky => "sky".into(),
                EnvChoice::CubeMap => "cube map (six images)".into(),
                EnvChoice::Hdr(p) => format!(
                    "HDR {}",
                    p.file_stem().unwrap_or_default().to_string_lossy()
                ),
            };
            egui::ComboBox::from_id_salt("env")
                .selected_text(name(&s.environment))
                .width(220.0)
                .show_ui(ui, |ui| {
                    let mut choices = vec![
                        EnvChoice::FromScene,
                        EnvChoice::None,
                        EnvChoice::Sky,
                        EnvChoice::CubeMap,
                    ];
                    choices.extend(state.hdrs.iter().cloned().map(EnvChoice::Hdr));
                    for c in choices {
                        let label = name(&c);
                        ui.selectable_value(&mut s.environment, c, label);
                    }
                });
            ui.add(egui::Slider::new(&mut s.env_intensity, 0.0..=4.0).text("intensity"));
            ui.add(
                egui::Slider::new(&mut s.env_rotation_deg, -180.0..=180.0).text("rotation (deg)"),
            );
        });
}

fn bvh_section(
    ui: &mut egui::Ui,
    b: &mut crate::bvh::BuildOptions,
    bvh: &SceneBvh,
    building: &BvhBuilding,
) {
    egui::CollapsingHeader::new("BVH")
        .default_open(true)
        .show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.radio_value(&mut b.split, SplitMethod::Sah, "binned SAH");
                ui.radio_value(&mut b.split, SplitMethod::Median, "median");
            });
            ui.add_enabled(
                b.split == SplitMethod::Sah,
                egui::Slider::new(&mut b.bins, 2..=64).text("bins"),
            );
            ui.add(egui::Slider::new(&mut b.max_leaf_size, 1..=32).text("leaf size"));
            if let Some(secs) = building.elapsed() {
                ui.horizontal(|ui| {
                    ui.spinner();
                    ui.label(format!("building... {secs:.1} s"));
                });
            }
            if let Some(t) = &bvh.bvh {
                let st = &t.stats;
                egui::Grid::new("bvh stats").show(ui, |ui| {
                    for (k, v) in [
                        ("triangles", st.triangles.to_string()),
                        ("nodes", st.nodes.to_string()),
                        ("leaves", st.leaves.to_string()),
                        ("levels", st.levels.to_string()),
                        (
                            "leaf size",
                            format!(
                                "{}..{} (mean {:.2})",
                                st.min_leaf_size, st.max_leaf_size, st.mean_leaf_size
                            ),
                        ),
                        ("SAH cost", format!("{:.2}", st.sah_cost)),
                        ("build", format!("{:.1} ms", st.build_ms)),
                        (
                            "left out",
                            format!("{} non-finite, {} zero-area", st.excluded, st.degenerate),
                        ),
                    ] {
                        ui.label(k);
                        ui.label(v);
                        ui.end_row();
                    }
                });
            }
        });
}

fn gizmo_section(
    ui: &mut egui::Ui,
    s: &mut ViewSettings,
    index: &BvhIndex,
    leaves: &mut LeafView,
    store: &mut GizmoConfigStore,
    debug: &mut DebugRay,
) {
    egui::CollapsingHeader::new("Gizmos and debug")
        .default_open(true)
        .show(ui, |ui| {
            ui.label(format!("boxes of {}", index.what));
            ui.checkbox(
                &mut store.config_mut::<BvhLevelGizmos>().0.enabled,
                "BVH level boxes (B)",
            );
            // Sliders only once the tree is indexed: a slider clamps its value to its range,
            // and an empty range would lose the level or leaf asked for at start.
            if let Some(depth) = index.levels.len().checked_sub(1) {
                ui.add(
                    egui::Slider::new(&mut s.level, 0..=depth as u32)
                        .clamping(egui::SliderClamping::Edits)
                        .text("level ([ ])"),
                );
            }
            if let Some(n) = index.levels.get(s.level as usize) {
                ui.small(format!("{} boxes at level {}", n.len(), s.level));
            }
            ui.checkbox(
                &mut store.config_mut::<LeafGizmos>().0.enabled,
                "BVH leaves (L)",
            );
            ui.horizontal(|ui| {
                ui.radio_value(&mut leaves.all, true, "all");
                ui.radio_value(&mut leaves.all, false, "one, with triangles");
            });
            if let Some(last) = index.leaves.len().checked_sub(1) {
                ui.add_enabled(
                    !leaves.all,
                    egui::Slider::new(&mut leaves.index, 0..=last as u32)
                        .clamping(egui::SliderClamping::Edits)
                        .text("leaf (, .)"),
                );
            }
            if leaves.all && index.leaves.len() > leaves.max_boxes {
                ui.small(format!(
                    "drawing the first {} of {} leaves",
                    leaves.max_boxes,
                    index.leaves.len()
                ));
            }
            ui.checkbox(
                &mut store.config_mut::<DebugRayGizmos>().0.enabled,
                "debug ray (R, click)",
            );
            ui.checkbox(&mut debug.show_nodes, "nodes the debug ray entered");
            debug_ray_text(ui, debug);
        });
}

fn debug_ray_text(ui: &mut egui::Ui, debug: &DebugRay) {
    let Some(p) = debug.pixel else {
        ui.small("Click the image to shoot a debug ray.");
        return;
    };
    ui.small(format!("ray through pixel ({:.0}, {:.0})", p.x, p.y));
    for (i, seg) in debug.path.segments.iter().enumerate() {
        let wasted = seg.nodes.iter().filter(|n| !n.found_hit).count();
        let hit = match seg.hit {
            Some(h) => format!("hit triangle {} at t = {:.4}", h.prim, h.t),
            None => "left the scene".into(),
        };
        ui.small(format!(
            "{i}: {:?}: {hit}; {} nodes entered, {wasted} for nothing",
            seg.kind,
            seg.nodes.len()
        ));
    }
    for sh in &debug.path.shadows {
        let (c, word) = match sh.state() {
            ShadowState::Visible => (egui::Color32::from_rgb(80, 230, 90), "visible"),
            ShadowState::Blocked => (egui::Color32::from_rgb(240, 70, 50), "blocked"),
            ShadowState::Attenuated => (egui::Color32::from_rgb(250, 160, 40), "attenuated"),
        };
        let f = sh.transmittance;
        ui.colored_label(
            c,
            format!(
                "segment {} -> light {}: {word}, passes ({:.2}, {:.2}, {:.2})",
                sh.segment, sh.light, f.x, f.y, f.z
            ),
        );
    }
}
