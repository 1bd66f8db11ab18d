"""The flight's stated defaults: how wrong the forecast is and how noisy the sensors are. The world
draws its errors with them and the operator is told them; neither imports the other."""

__all__ = ["DEFAULT_FORECAST_SIGMA_KT", "DEFAULT_SENSOR_NOISE_MA", "DEFAULT_SENSOR_NOISE_MV"]

DEFAULT_FORECAST_SIGMA_KT = 13.0  # kt, std of the forecast error of each destination's wind
DEFAULT_SENSOR_NOISE_MV = 5.0  # mV, std of the voltage sensor's Gaussian noise
DEFAULT_SENSOR_NOISE_MA = 20.0  # mA, std of the current sensor's Gaussian noise
