"""VectorNav VN-100 IMU: binary/ASCII protocol, frame conversions, serial driver and fake device.

Pure modules (no ROS): :mod:`.protocol` (framing, CRC, commands), :mod:`.conversions` (NED/FRD to
ENU/FLU, REP-103/145), :mod:`.driver` (handshake, streaming, reconnect over a pyserial-like port),
:mod:`.fake` (byte-level fake sensor, in-memory port, pty bridge for the simulated robot).
"""
from quadruped_drivers.vn100.conversions import ImuReading, ros_to_vn, vn_to_ros
from quadruped_drivers.vn100.driver import Vn100Driver, Vn100Error, serial_port_factory
from quadruped_drivers.vn100.protocol import BinaryPacketParser, Vn100Sample

__all__ = ["BinaryPacketParser", "ImuReading", "Vn100Driver", "Vn100Error", "Vn100Sample",
           "ros_to_vn", "serial_port_factory", "vn_to_ros"]
