"""Physical constants (SI units) shared by the simulator and the estimators."""
EARTH_RATE_RAD_S = 7.2921150e-5  # WGS-84 sidereal rotation rate, rad/s
STANDARD_GRAVITY_M_S2 = 9.80665  # m/s^2
