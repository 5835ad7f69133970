"""Real robots behind the Environment protocol: the DJI Tello (djitellopy) and a Tello SDK emulator for tests."""
