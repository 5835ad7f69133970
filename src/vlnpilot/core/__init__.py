"""The floor: errors, records, commands, the FSM, the pilot contract, the environment protocol, run directories."""
