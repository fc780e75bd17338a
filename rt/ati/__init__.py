"""ATI force/torque sensors: Net F/T over UDP (RDT) and over CAN."""
