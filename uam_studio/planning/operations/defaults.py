"""The flight's stated defaults: how wrong the forecast is and how noisy the sensors are (the world
draws its errors with them and the operator is told them; neither imports the other), and the weather
reserve the operator keeps."""

__all__ = ["DEFAULT_FORECAST_SIGMA_KT", "DEFAULT_SENSOR_NOISE_MA", "DEFAULT_SENSOR_NOISE_MV", "WEATHER_RESERVE_KT"]

DEFAULT_FORECAST_SIGMA_KT = 13.0  # kt, std of the forecast error of each destination's wind
DEFAULT_SENSOR_NOISE_MV = 5.0  # mV, std of the voltage sensor's Gaussian noise
DEFAULT_SENSOR_NOISE_MA = 20.0  # mA, std of the current sensor's Gaussian noise
# kt of headwind beyond the belief every take-off keeps the next leg and the way home safe under
WEATHER_RESERVE_KT = 25.0
