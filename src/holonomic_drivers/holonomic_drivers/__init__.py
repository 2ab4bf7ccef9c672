"""Motor drive backends over CAN and their emulators (see README.md)."""
