"""The NMPC baseline controller: problem, reference, settings, spin turns, plan pricing, settings comparison."""
