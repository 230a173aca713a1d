//! Radiance split by component, as the paper's equation L = L_e + L_d + L_s + L_a splits it.

use glam::Vec3;
use std::ops::{Add, AddAssign, Mul};

/// The four components of the light leaving a primary hit towards the eye. `specular` holds all
/// light that reached the eye through specular reflection or transmission, whatever it was at
/// the far end, so the four always add up to the pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Components {
    pub emission: Vec3,
    pub direct: Vec3,
    pub specular: Vec3,
    pub indirect: Vec3,
}

impl Components {
    pub fn total(&self) -> Vec3 {
        self.emission + self.direct + self.specular + self.indirect
    }

    pub fn as_array(&self) -> [Vec3; 4] {
        [self.emission, self.direct, self.specular, self.indirect]
    }
}

impl Add for Components {
    type Output = Components;
    fn add(self, o: Components) -> Components {
        Components {
            emission: self.emission + o.emission,
            direct: self.direct + o.direct,
            specular: self.specular + o.specular,
            indirect: self.indirect + o.indirect,
        }
    }
}

impl AddAssign for Components {
    fn add_assign(&mut self, o: Components) {
        *self = *self + o;
    }
}

impl Mul<f32> for Components {
    type Output = Components;
    fn mul(self, s: f32) -> Components {
        Components {
            emission: self.emission * s,
            direct: self.direct * s,
            specular: self.specular * s,
            indirect: self.indirect * s,
        }
    }
}
