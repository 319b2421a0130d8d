"""Transducers as a machine has them: 4-20 mA loops read by a 12-bit ADC.

Each transducer maps its range linearly onto 4-20 mA. Its zero sits off by up to +-0.5 % of
full scale and its span by up to +-0.5 % (drawn once per machine), white noise rides on the
current, the loop saturates at 3.8 and 20.5 mA (NAMUR NE 43), and the controller's 12-bit ADC
over 0-25 mA quantises it (about 0.15 bar on a 400 bar transducer).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MA_LO, MA_SPAN = 4.0, 16.0
MA_MIN, MA_MAX = 3.8, 20.5
ADC_FULL_MA, ADC_BITS = 25.0, 12
ADC_LSB_MA = ADC_FULL_MA / 2**ADC_BITS

# name: (full scale in the signal's unit, noise rms in that unit)
TRANSDUCERS = {
    "PP": (400.0, 0.3),
    "PA": (400.0, 0.3),
    "PB": (400.0, 0.3),
    "QP": (60.0, 0.1),
    "RodPos": (500.0, 0.5),
}


@dataclass(frozen=True)
class Transducer:
    """One transducer's range and its drawn calibration error."""

    full_scale: float
    noise_rms: float
    offset_fs: float  # zero error, share of full scale
    gain: float  # span error: reading = gain * value + offset

    @classmethod
    def draw(
        cls,
        rng: np.random.Generator,
        full_scale: float,
        noise_rms: float,
        offset_limit_fs: float = 0.005,
        gain_limit: float = 0.005,
    ) -> Transducer:
        return cls(
            full_scale,
            noise_rms,
            float(rng.uniform(-offset_limit_fs, offset_limit_fs)),
            float(1.0 + rng.uniform(-gain_limit, gain_limit)),
        )

    def current_ma(self, value: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Loop current for the true value: calibration error, noise, saturation."""
        share = self.gain * np.asarray(value, dtype=np.float64) / self.full_scale + self.offset_fs
        ma = MA_LO + MA_SPAN * share
        ma = ma + rng.normal(0.0, MA_SPAN * self.noise_rms / self.full_scale, ma.shape)
        return np.clip(ma, MA_MIN, MA_MAX)

    def read(self, value: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """What the controller reports: the ADC code of the current, scaled back to units."""
        code = np.round(self.current_ma(value, rng) / ADC_LSB_MA)
        return (code * ADC_LSB_MA - MA_LO) / MA_SPAN * self.full_scale


def draw_transducers(rng: np.random.Generator) -> dict[str, Transducer]:
    """One machine's set of transducers."""
    return {name: Transducer.draw(rng, fs, noise) for name, (fs, noise) in TRANSDUCERS.items()}


def oil_temp_reading(
    temp_c: np.ndarray, rng: np.random.Generator, sample_s: float = 0.01, offset_c: float = 0.0
) -> np.ndarray:
    """An oil temperature sensor read at 1 Hz (held between readings), 0.1 degC resolution."""
    per = int(round(1.0 / sample_s))
    held = np.repeat(temp_c[::per], per)[: len(temp_c)]
    noisy = (
        held + offset_c + np.repeat(rng.normal(0.0, 0.1, len(temp_c[::per])), per)[: len(temp_c)]
    )
    return np.round(noisy, 1)
