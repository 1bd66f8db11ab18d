"""The flight's stated defaults: how wrong the forecast is and how noisy the sensors are (the world
draws its errors with them and the operator is told them; neither imports the other), the weather
reserve the operator keeps at the default declared risk (from :mod:`uam_studio.risk`), and the voltage noise its
health fits are told (:func:`fit_noise_v`)."""

from uam_studio.risk import WEATHER_RESERVE_KT

__all__ = ["DEFAULT_FORECAST_SIGMA_KT", "DEFAULT_SENSOR_NOISE_MA", "DEFAULT_SENSOR_NOISE_MV", "FIT_NOISE_FLOOR_MV",
           "WEATHER_RESERVE_KT", "fit_noise_v"]

DEFAULT_FORECAST_SIGMA_KT = 13.0  # kt, std of the forecast error of each destination's wind
DEFAULT_SENSOR_NOISE_MV = 5.0  # mV, std of the voltage sensor's Gaussian noise
DEFAULT_SENSOR_NOISE_MA = 20.0  # mA, std of the current sensor's Gaussian noise
FIT_NOISE_FLOOR_MV = 0.5  # mV: the least voltage noise a health fit is told (a noiseless sensor still has a model)


def fit_noise_v(sensor_noise_mv: float) -> float:
    """The voltage noise std (V) the health fits are told for a sensor of ``sensor_noise_mv`` (mV): never below
    :data:`FIT_NOISE_FLOOR_MV`."""
    return max(float(sensor_noise_mv), FIT_NOISE_FLOOR_MV) * 1e-3
