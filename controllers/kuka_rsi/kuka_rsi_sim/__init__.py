"""A KUKA KR C4 running RobotSensorInterface (RSI), simulated: the controller side.

A separate machine from rob6: it shares no code with it and is written from the
protocol's public description. See controllers/kuka_rsi/README.md.
"""

__version__ = "0.1.0"
