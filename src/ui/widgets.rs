//! Small widgets that more than one panel uses (no panel imports here).

use eframe::egui::{Slider, Ui};
use glam::Vec3;

/// An RGB radiometric quantity as a colour and a logarithmic strength of
/// at most `max` (the lights' and the sky's controls).
pub fn rgb_intensity_ui(ui: &mut Ui, value: &mut Vec3, label: &str, tip: &str, max: f32) {
    let strength = value.max_element();
    let tint = if strength > 0.0 {
        *value / strength
    } else {
        Vec3::ONE
    };
    let mut rgb = [tint.x, tint.y, tint.z];
    let mut s = strength;
    ui.horizontal(|ui| {
        let c = ui.color_edit_button_rgb(&mut rgb).on_hover_text(tip);
        let r = ui
            .add(Slider::new(&mut s, 0.0..=max).logarithmic(true).text(label))
            .on_hover_text(tip);
        if c.changed() || r.changed() {
            *value = Vec3::from(rgb).max(Vec3::ZERO) * s;
        }
    });
}
