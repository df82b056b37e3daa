//! The bar positions the downbeat network tells apart and the bar pointer counts through.
//!
//! The beat tracker may follow the music at its counted beat, at twice it (eighth notes, a
//! slow song tracked double time) or at half of it (a fast 4/4 song tracked on 1 and 3). Each
//! class says which of these the tracked beats are and where the newest tracked beat stands:
//! its position counted in tracked beats through one bar (double time: odd positions are on
//! the counted beats, even ones halfway between; half time: the counted beat it lies on).

/// How the tracked beats relate to the counted ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// One tracked beat per counted beat.
    Beat,
    /// Two tracked beats per counted beat.
    Double,
    /// One tracked beat per two counted beats.
    Half,
}

/// One bar position of the tracked beats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BarClass {
    /// How the tracked beats relate to the counted ones.
    pub level: Level,
    /// Counted beats per bar.
    pub meter: usize,
    /// Position of the tracked beat: in tracked beats from 1 ([`Level::Beat`],
    /// [`Level::Double`]), or the counted beat it lies on ([`Level::Half`]).
    pub position: usize,
}

/// Every class, in the order of the network's outputs.
pub const CLASSES: [BarClass; 25] = [
    BarClass {
        level: Level::Beat,
        meter: 4,
        position: 1,
    },
    BarClass {
        level: Level::Beat,
        meter: 4,
        position: 2,
    },
    BarClass {
        level: Level::Beat,
        meter: 4,
        position: 3,
    },
    BarClass {
        level: Level::Beat,
        meter: 4,
        position: 4,
    },
    BarClass {
        level: Level::Beat,
        meter: 3,
        position: 1,
    },
    BarClass {
        level: Level::Beat,
        meter: 3,
        position: 2,
    },
    BarClass {
        level: Level::Beat,
        meter: 3,
        position: 3,
    },
    BarClass {
        level: Level::Double,
        meter: 4,
        position: 1,
    },
    BarClass {
        level: Level::Double,
        meter: 4,
        position: 2,
    },
    BarClass {
        level: Level::Double,
        meter: 4,
        position: 3,
    },
    BarClass {
        level: Level::Double,
        meter: 4,
        position: 4,
    },
    BarClass {
        level: Level::Double,
        meter: 4,
        position: 5,
    },
    BarClass {
        level: Level::Double,
        meter: 4,
        position: 6,
    },
    BarClass {
        level: Level::Double,
        meter: 4,
        position: 7,
    },
    BarClass {
        level: Level::Double,
        meter: 4,
        position: 8,
    },
    BarClass {
        level: Level::Double,
        meter: 3,
        position: 1,
    },
    BarClass {
        level: Level::Double,
        meter: 3,
        position: 2,
    },
    BarClass {
        level: Level::Double,
        meter: 3,
        position: 3,
    },
    BarClass {
        level: Level::Double,
        meter: 3,
        position: 4,
    },
    BarClass {
        level: Level::Double,
        meter: 3,
        position: 5,
    },
    BarClass {
        level: Level::Double,
        meter: 3,
        position: 6,
    },
    BarClass {
        level: Level::Half,
        meter: 4,
        position: 1,
    },
    BarClass {
        level: Level::Half,
        meter: 4,
        position: 2,
    },
    BarClass {
        level: Level::Half,
        meter: 4,
        position: 3,
    },
    BarClass {
        level: Level::Half,
        meter: 4,
        position: 4,
    },
];
/// Outputs of the downbeat network.
pub const CLASS_COUNT: usize = CLASSES.len();

impl BarClass {
    /// The class of the next tracked beat.
    pub fn next(self) -> Self {
        let position = match self.level {
            Level::Beat => self.position % self.meter + 1,
            Level::Double => self.position % (2 * self.meter) + 1,
            Level::Half => (self.position + 1) % self.meter + 1,
        };
        Self { position, ..self }
    }

    /// The counted beat the tracked beat lies on (1 = downbeat), or `None` for a tracked beat
    /// halfway between two counted ones.
    pub fn counted_position(self) -> Option<usize> {
        match self.level {
            Level::Double if self.position.is_multiple_of(2) => None,
            Level::Double => Some(self.position.div_ceil(2)),
            _ => Some(self.position),
        }
    }

    /// The counted beat most recently reached when this tracked beat sounds.
    pub fn last_counted_position(self) -> usize {
        match self.level {
            Level::Double => self.position.div_ceil(2),
            _ => self.position,
        }
    }

    /// Counted beats per tracked beat.
    pub fn counted_per_tracked(self) -> f64 {
        match self.level {
            Level::Beat => 1.0,
            Level::Double => 0.5,
            Level::Half => 2.0,
        }
    }
}

/// The index of a class in [`CLASSES`], if it is one.
pub fn class_index(class: BarClass) -> Option<usize> {
    CLASSES.iter().position(|&c| c == class)
}

/// The index of position `position` in a bar of `meter` beats, tracked at the counted beat.
pub fn beat_class_index(meter: usize, position: usize) -> Option<usize> {
    class_index(BarClass {
        level: Level::Beat,
        meter,
        position,
    })
}

/// The index of the class that follows class `index` one tracked beat later.
pub fn successor(index: usize) -> usize {
    class_index(CLASSES[index].next()).unwrap_or(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(level: Level, meter: usize, from: usize, n: usize) -> Vec<usize> {
        let mut c = BarClass {
            level,
            meter,
            position: from,
        };
        (0..n)
            .map(|_| {
                let p = c.position;
                c = c.next();
                p
            })
            .collect()
    }

    #[test]
    fn every_class_counts_round_its_bar() {
        assert_eq!(count(Level::Beat, 4, 1, 5), [1, 2, 3, 4, 1]);
        assert_eq!(count(Level::Beat, 3, 2, 4), [2, 3, 1, 2]);
        assert_eq!(count(Level::Double, 3, 5, 4), [5, 6, 1, 2]);
        assert_eq!(count(Level::Half, 4, 1, 3), [1, 3, 1]);
        assert_eq!(count(Level::Half, 4, 2, 3), [2, 4, 2]);
        for (i, c) in CLASSES.iter().enumerate() {
            assert_eq!(CLASSES[successor(i)], c.next(), "{c:?}");
        }
    }

    #[test]
    fn double_time_counts_only_its_odd_beats() {
        let on = |p| {
            BarClass {
                level: Level::Double,
                meter: 4,
                position: p,
            }
            .counted_position()
        };
        assert_eq!(
            (1..=8).map(on).collect::<Vec<_>>(),
            [Some(1), None, Some(2), None, Some(3), None, Some(4), None]
        );
    }
}
