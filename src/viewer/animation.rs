//! Playing the scene's glTF animations: a timeline (the time shown, play and pause, speed)
//! whose instants are loaded off the frame as the scene at that time
//! ([`crate::scene::Scene::load_at`]); the BVH and the picture follow each one as they follow
//! any new scene, and the camera stays where the user has it. Playing loops over the
//! animation's length; while one instant loads, the timeline runs on, and the next load asks
//! for the time reached.

use bevy::prelude::*;

use super::UiFocus;
use super::scene::{CurrentScene, SceneLoading, SceneSystems, ShowInstant};

/// The timeline and its systems.
pub struct AnimationPlugin {
    /// Read the Space key (false under `MinimalPlugins`).
    pub interactive: bool,
}

impl Plugin for AnimationPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<Timeline>().add_systems(
            PreUpdate,
            (new_file, advance, request).chain().before(SceneSystems),
        );
        if self.interactive {
            app.add_systems(Update, space_plays);
        }
    }
}

/// Where the animation is, and how it runs.
#[derive(Resource, Clone, Debug, PartialEq)]
pub struct Timeline {
    /// The time asked for, in seconds (from 0 to the animation's length).
    pub time: f64,
    /// Whether time runs.
    pub playing: bool,
    /// Seconds of animation per second of real time.
    pub speed: f64,
    /// The instant last asked for, so a time that failed to load is not asked for again.
    asked: Option<f64>,
    /// The generation of the scene the timeline last saw installed.
    seen: u64,
    /// Where the first file opened starts (time, playing); later files start at 0, paused.
    first: Option<(f64, bool)>,
}

impl Timeline {
    /// A timeline whose first file starts at `time`, playing or not.
    pub fn starting(time: f64, playing: bool) -> Self {
        Timeline {
            first: Some((time, playing)),
            ..Timeline::default()
        }
    }
}

impl Default for Timeline {
    fn default() -> Self {
        Timeline {
            time: 0.0,
            playing: false,
            speed: 1.0,
            asked: None,
            seen: 0,
            first: None,
        }
    }
}

/// The range of the speed slider.
pub const SPEEDS: std::ops::RangeInclusive<f64> = 0.05..=4.0;

/// A new file starts its timeline at 0, paused, or where [`Timeline::starting`] asked for
/// the first file (another instant of the same file keeps the timeline as it is).
fn new_file(current: Res<CurrentScene>, mut timeline: ResMut<Timeline>) {
    if current.generation == timeline.seen {
        return;
    }
    timeline.seen = current.generation;
    if current.reframe {
        let (time, playing) = match current.source {
            Some(_) => timeline.first.take().unwrap_or((0.0, false)),
            None => (0.0, false),
        };
        let length = current.scene.animation.map_or(0.0, f64::from);
        timeline.time = time.clamp(0.0, length);
        timeline.playing = playing;
        timeline.asked = None;
    }
}

/// Runs the time while playing, looping over the animation's length.
fn advance(time: Res<Time<Real>>, current: Res<CurrentScene>, mut timeline: ResMut<Timeline>) {
    let Some(length) = current.scene.animation.map(f64::from) else {
        return;
    };
    if !timeline.playing {
        return;
    }
    let t = timeline.time + time.delta_secs_f64() * timeline.speed;
    timeline.time = if length > 0.0 {
        t.rem_euclid(length)
    } else {
        0.0
    };
}

/// Asks for the instant the timeline is at when the scene shows another and no load is
/// under way.
fn request(
    current: Res<CurrentScene>,
    loading: Res<SceneLoading>,
    mut timeline: ResMut<Timeline>,
    mut show: MessageWriter<ShowInstant>,
) {
    if current.scene.animation.is_none() || current.source.is_none() || loading.busy() {
        return;
    }
    let t = timeline.time;
    if current.time != Some(t) && timeline.asked != Some(t) {
        timeline.asked = Some(t);
        show.write(ShowInstant(t));
    }
}

/// Space plays and pauses.
fn space_plays(
    input: Res<ButtonInput<KeyCode>>,
    focus: Res<UiFocus>,
    current: Res<CurrentScene>,
    mut timeline: ResMut<Timeline>,
) {
    if !focus.keyboard && current.scene.animation.is_some() && input.just_pressed(KeyCode::Space) {
        timeline.playing = !timeline.playing;
    }
}

/// The inspector's timeline: play and pause, the time (dragging it scrubs), the speed; the
/// timeline changed, if the user changed it. Shown only for a scene with animations.
pub fn section(
    ui: &mut bevy_egui::egui::Ui,
    timeline: &Timeline,
    current: &CurrentScene,
) -> Option<Timeline> {
    use bevy_egui::egui;
    let length = current.scene.animation.map(f64::from)?;
    ui.separator();
    ui.strong("Animation");
    let mut t = timeline.clone();
    ui.horizontal(|ui| {
        let label = if t.playing {
            "Pause (Space)"
        } else {
            "Play (Space)"
        };
        if ui.button(label).clicked() {
            t.playing = !t.playing;
        }
        if ui.button("Start").clicked() {
            t.time = 0.0;
        }
    });
    ui.add(
        egui::Slider::new(&mut t.time, 0.0..=length.max(1e-3))
            .text("time (s)")
            .fixed_decimals(2),
    );
    ui.add(
        egui::Slider::new(&mut t.speed, SPEEDS)
            .logarithmic(true)
            .text("speed")
            .fixed_decimals(2),
    );
    let shown = current
        .time
        .map_or("as placed".to_string(), |s| format!("{s:.2} s"));
    ui.label(format!("{length:.2} s long; showing {shown}"));
    (t != *timeline).then_some(t)
}
