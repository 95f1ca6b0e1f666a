"""The trainers: PPO for the dense teacher, TD3 for the contact-primitive policy, DAgger for the
camera student. They sit above rl/workers/ because each may spread its episodes over Ray
workers; nothing below this room imports it."""
